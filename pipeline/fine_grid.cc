#include "pipeline/fine_grid.h"

#include <opencv2/imgproc.hpp>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "capture/opencv_bridge.h"
#include "core/parallel.h"

namespace u3mscan {
namespace {

// Where the height's long wavelengths (from the maps' grid) meet its detail (from the fine grid):
// sigma of the Gaussian that splits them, map pixels (measured: 4 and 8 give the same heights to
// within 0.1 % of the range on plain, velvet and satin at 2x and 3x).
constexpr double kHeightSplitSigmaPx = 4.0;

// `image` resized by `scale` (k: onto RefineGrid, 1/k: back onto the maps' grid) per plane with
// OpenCV: INTER_LINEAR samples at the fine pixels' centres with the edges clamped, INTER_NEAREST
// repeats each pixel k x k times, and INTER_AREA at 1/k is each k x k block's mean.
Image Resize(const Image& image, double scale, int interpolation, double pitch_mm) {
  const int w = static_cast<int>(std::lround(image.width() * scale));
  const int h = static_cast<int>(std::lround(image.height() * scale));
  Image out(w, h, image.channels(), 0.0f, pitch_mm);
  for (int c = 0; c < image.channels(); ++c) {
    cv::Mat to = internal::PlaneView(out, c);
    cv::resize(internal::PlaneView(image, c), to, to.size(), 0.0, 0.0, interpolation);
  }
  return out;
}

long long InMapPixels(long long fine_count, int k) { return (fine_count + k * k / 2) / (k * k); }

}  // namespace

MetricGrid RefineGrid(const MetricGrid& grid, int k) {
  MetricGrid fine = grid;
  fine.width = grid.width * k;
  fine.height = grid.height * k;
  fine.pitch_mm = grid.pitch_mm / k;
  return fine;
}

CalibrationResult FineCalibration(const CalibrationResult& calibration, int k) {
  CalibrationResult fine = calibration;
  fine.grid = RefineGrid(calibration.grid, k);
  for (FlatCalibration& flat : fine.flats) flat.irradiance = UpsampleLinear(flat.irradiance, k);
  return fine;
}

Image GaussianBlurPlane(const Image& in, double sigma_px) {
  Image out(in.width(), in.height(), 1, 0.0f, in.pitch_mm());
  const int size = 2 * std::max(1, static_cast<int>(std::ceil(3.0 * sigma_px))) + 1;
  cv::Mat to = internal::PlaneView(out, 0);
  cv::GaussianBlur(internal::PlaneView(in, 0), to, cv::Size(size, size), sigma_px, sigma_px, cv::BORDER_REFLECT);
  return out;
}

Image UpsampleLinear(const Image& coarse, int k) { return Resize(coarse, k, cv::INTER_LINEAR, coarse.pitch_mm() / k); }
Image UpsampleNearest(const Image& coarse, int k) { return Resize(coarse, k, cv::INTER_NEAREST, coarse.pitch_mm() / k); }
Image BlockMean(const Image& fine, int k, double pitch_mm) { return Resize(fine, 1.0 / k, cv::INTER_AREA, pitch_mm); }

// cv::resize has no max pooling.
Image BlockMax(const Image& fine, int k, double pitch_mm) {
  const int w = fine.width() / k, h = fine.height() / k;
  Image out(w, h, fine.channels(), 0.0f, pitch_mm);
  for (int ch = 0; ch < fine.channels(); ++ch) {
    for (int row = 0; row < h; ++row) {
      for (int col = 0; col < w; ++col) {
        float largest = fine.at(ch, row * k, col * k);
        for (int j = 0; j < k; ++j) {
          for (int i = 0; i < k; ++i) largest = std::max(largest, fine.at(ch, row * k + j, col * k + i));
        }
        out.at(ch, row, col) = largest;
      }
    }
  }
  return out;
}

Image SurfaceAreaWeights(const Image& fine_normals, const reconstruction::ViewParallax& parallax, int fine_row0) {
  if (!parallax.enabled || fine_normals.empty()) return Image();
  Image weights(fine_normals.width(), fine_normals.height(), 1, 1.0f, fine_normals.pitch_mm());
  const int w = fine_normals.width();
  const float* x = fine_normals.plane(0).data();
  const float* y = fine_normals.plane(1).data();
  const float* z = fine_normals.plane(2).data();
  float* out = weights.plane(0).data();
  // The slope of a facet seen edge-on is unbounded; a stretch at min_stretch bounds its weight.
  constexpr double kMinNormalZ = 0.05;
  ParallelFor(static_cast<std::size_t>(fine_normals.height()), [&](std::size_t r0, std::size_t r1) {
    for (std::size_t r = r0; r < r1; ++r) {
      for (int c = 0; c < w; ++c) {
        const std::size_t i = r * w + c;
        if (!std::isfinite(x[i]) || !std::isfinite(y[i]) || !std::isfinite(z[i])) continue;  // keeps 1
        const double nz = std::max(static_cast<double>(z[i]), kMinNormalZ);
        const double stretch = reconstruction::ParallaxStretch(parallax, fine_normals.pitch_mm(), c,
                                                               fine_row0 + static_cast<int>(r), -x[i] / nz, -y[i] / nz);
        out[i] = static_cast<float>(1.0 / stretch);
      }
    }
  });
  return weights;
}

Image BlockWeightedMean(const Image& fine, const Image& weights, int k, double pitch_mm) {
  if (weights.empty()) return BlockMean(fine, k, pitch_mm);
  if (weights.width() != fine.width() || weights.height() != fine.height() || weights.channels() != 1)
    throw std::invalid_argument("BlockWeightedMean: weights must be one plane of the image's size");
  // Summed in place, block by block: no weighted copy of the fine image (36 MP: 0.4 GB).
  const int w = fine.width() / k, h = fine.height() / k;
  Image out(w, h, fine.channels(), 0.0f, pitch_mm);
  ParallelFor(static_cast<std::size_t>(h), [&](std::size_t r0, std::size_t r1) {
    for (std::size_t r = r0; r < r1; ++r) {
      const int row = static_cast<int>(r);
      for (int col = 0; col < w; ++col) {
        double total = 0.0;
        for (int j = 0; j < k; ++j) {
          for (int i = 0; i < k; ++i) total += weights.at(0, row * k + j, col * k + i);
        }
        for (int ch = 0; ch < fine.channels(); ++ch) {
          double sum = 0.0;
          for (int j = 0; j < k; ++j) {
            for (int i = 0; i < k; ++i) {
              sum += static_cast<double>(weights.at(0, row * k + j, col * k + i)) * fine.at(ch, row * k + j, col * k + i);
            }
          }
          out.at(ch, row, col) = total > 0.0 ? static_cast<float>(sum / total) : 0.0f;
        }
      }
    }
  });
  return out;
}

Image AverageNormalsOntoMaps(const Image& fine_normals, int k, double pitch_mm, const Image& weights,
                             const PlanPlacement& placement) {
  Image out = PlacedWeightedMean(fine_normals, weights, placement, k, pitch_mm);
  const std::size_t n = out.pixel_count();
  float* x = out.plane(0).data();
  float* y = out.plane(1).data();
  float* z = out.plane(2).data();
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f v(x[i], y[i], z[i]);
    const float length = v.norm();
    const Eigen::Vector3f u = length > 1e-6f && std::isfinite(length) ? Eigen::Vector3f(v / length) : Eigen::Vector3f::UnitZ();
    x[i] = u.x(), y[i] = u.y(), z[i] = u.z();
  }
  return out;
}

reconstruction::PhotometricStereoResult AveragePhotometricStereoOntoMaps(const reconstruction::PhotometricStereoResult& f,
                                                                         int k, double pitch_mm,
                                                                         const reconstruction::ViewParallax& parallax,
                                                                         int fine_row0, const PlanPlacement& placement) {
  if (placement.enabled() && fine_row0 != 0) {
    throw std::invalid_argument("AveragePhotometricStereoOntoMaps: a placement is made for the whole fine grid (row 0)");
  }
  reconstruction::PhotometricStereoResult ps;
  const Image weights = SurfaceAreaWeights(f.normal, parallax, fine_row0);
  ps.normal = AverageNormalsOntoMaps(f.normal, k, pitch_mm, weights, placement);
  ps.albedo = PlacedWeightedMean(f.albedo, weights, placement, k, pitch_mm);
  ps.confidence = BlockMean(f.confidence, k, pitch_mm);
  ps.condition_number = BlockMax(f.condition_number, k, pitch_mm);
  ps.used_lights = BlockMean(f.used_lights, k, pitch_mm);
  if (!f.height_mm.empty()) ps.height_mm = PlacedWeightedMean(f.height_mm, weights, placement, k, pitch_mm);
  ps.ill_conditioned_pixels = InMapPixels(f.ill_conditioned_pixels, k);
  ps.dark_pixels = InMapPixels(f.dark_pixels, k);
  ps.low_albedo_pixels = InMapPixels(f.low_albedo_pixels, k);
  ps.clamped_normal_pixels = InMapPixels(f.clamped_normal_pixels, k);
  ps.regularised_pixels = InMapPixels(f.regularised_pixels, k);
  ps.near_iterations = f.near_iterations;
  ps.diffuse_roughness = f.diffuse_roughness;
  ps.last_normal_change_deg = f.last_normal_change_deg;
  return ps;
}

Image HeightFromFineAndMapsGrids(const Image& fine_height_mm, const Image& maps_height_mm, int k, const Image& weights,
                                 const PlanPlacement& placement) {
  Image height = PlacedWeightedMean(fine_height_mm, weights, placement, k, fine_height_mm.pitch_mm() * k);
  if (maps_height_mm.empty()) return height;
  const Image low = GaussianBlurPlane(maps_height_mm, kHeightSplitSigmaPx),
              detail_low = GaussianBlurPlane(height, kHeightSplitSigmaPx);
  for (std::size_t i = 0; i < height.pixel_count(); ++i) {
    height.data()[i] = low.data()[i] + height.data()[i] - detail_low.data()[i];
  }
  return height;
}

}  // namespace u3mscan
