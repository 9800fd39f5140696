#include "capture/rectification.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <opencv2/imgproc.hpp>

#include "capture/opencv_bridge.h"
#include "core/error.h"
#include "core/logging.h"
#include "core/parallel.h"
#include "core/units.h"

namespace u3mscan {
namespace {

bool Sees(const CameraModel& camera, const Eigen::Vector3d& point) {
  bool in_front = false;
  const Eigen::Vector2d pixel = camera.Project(point, &in_front);
  return in_front && pixel.x() >= 0.0 && pixel.y() >= 0.0 && pixel.x() <= camera.width - 1.0 &&
         pixel.y() <= camera.height - 1.0;
}

bool AllSee(const std::vector<CameraModel>& cameras, const Eigen::Vector3d& point) {
  return std::all_of(cameras.begin(), cameras.end(), [&](const CameraModel& c) { return Sees(c, point); });
}

}  // namespace

std::array<double, 4> CommonRegionMm(const std::vector<CameraModel>& cameras, double surface_z_mm) {
  // Start from the intersection of the footprints' bounding boxes, then pull in every side that
  // has a point some camera does not see, a small step at a time.
  double x0 = -1e300, y0 = -1e300, x1 = 1e300, y1 = 1e300;
  constexpr int kBorderSamples = 64;
  for (const auto& camera : cameras) {
    double cx0 = 1e300, cy0 = 1e300, cx1 = -1e300, cy1 = -1e300;
    for (int i = 0; i <= kBorderSamples; ++i) {
      const double t = static_cast<double>(i) / kBorderSamples;
      const Eigen::Vector2d border[] = {{t * (camera.width - 1), 0.0},
                                        {t * (camera.width - 1), camera.height - 1.0},
                                        {0.0, t * (camera.height - 1)},
                                        {camera.width - 1.0, t * (camera.height - 1)}};
      for (const auto& pixel : border) {
        Eigen::Vector3d p;
        if (!camera.PixelToPlane(pixel, surface_z_mm, &p)) continue;
        cx0 = std::min(cx0, p.x()), cx1 = std::max(cx1, p.x());
        cy0 = std::min(cy0, p.y()), cy1 = std::max(cy1, p.y());
      }
    }
    x0 = std::max(x0, cx0), y0 = std::max(y0, cy0), x1 = std::min(x1, cx1), y1 = std::min(y1, cy1);
  }
  if (!(x1 > x0 && y1 > y0)) return {0, 0, 0, 0};
  const double step = 0.002 * std::max(x1 - x0, y1 - y0);
  for (int iteration = 0; iteration < 2000 && x1 > x0 && y1 > y0; ++iteration) {
    bool moved = false;
    auto side_ok = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
      for (int i = 0; i <= kBorderSamples; ++i) {
        if (!AllSee(cameras, a + (b - a) * (static_cast<double>(i) / kBorderSamples))) return false;
      }
      return true;
    };
    const double z = surface_z_mm;
    if (!side_ok({x0, y0, z}, {x0, y1, z})) x0 += step, moved = true;
    if (!side_ok({x1, y0, z}, {x1, y1, z})) x1 -= step, moved = true;
    if (!side_ok({x0, y0, z}, {x1, y0, z})) y0 += step, moved = true;
    if (!side_ok({x0, y1, z}, {x1, y1, z})) y1 -= step, moved = true;
    if (!moved) return {x0, y0, x1, y1};
  }
  return {0, 0, 0, 0};
}

double SampleSurfaceZMm(const Manifest& manifest) { return manifest.sample.thickness_mm.value_or(0.0); }

MetricGrid ChooseGrid(const std::vector<CameraModel>& cameras, const OutputSpec& output,
                      const std::string& manifest_file, double surface_z_mm) {
  std::array<double, 4> region{};
  if (output.region_mm) {
    region = *output.region_mm;
  } else {
    if (cameras.empty()) throw InputError(manifest_file, "/cameras", "at least one camera with sample frames");
    region = CommonRegionMm(cameras, surface_z_mm);
    if (!(region[2] > region[0] && region[3] > region[1])) {
      throw InputError(manifest_file, "/output/region_mm",
                       "a region of the sample plane that every sample camera sees; the cameras share none");
    }
  }
  if (!(region[2] > region[0] && region[3] > region[1])) {
    throw InputError(manifest_file, "/output/region_mm", "[x0, y0, x1, y1] with x1 > x0 and y1 > y0 (mm)");
  }
  double dpi = 0.0;
  if (output.dpi) {
    dpi = *output.dpi;
    if (!(dpi > 0.0)) throw InputError(manifest_file, "/output/dpi", "a positive resolution in dots per inch");
  } else {
    const Eigen::Vector3d centre(0.5 * (region[0] + region[2]), 0.5 * (region[1] + region[3]), surface_z_mm);
    double finest_mm = 1e300;
    for (const auto& camera : cameras) {
      const double pitch = camera.PitchOnPlaneMm(centre);
      if (pitch > 0.0) finest_mm = std::min(finest_mm, pitch);
    }
    if (!(finest_mm < 1e300)) throw InputError(manifest_file, "/output/dpi", "a resolution (no camera sees the region)");
    dpi = std::max(1.0, std::floor(PitchMmToDpi(finest_mm)));
  }
  MetricGrid grid;
  grid.pitch_mm = DpiToPitchMm(dpi);
  grid.x0_mm = region[0];
  grid.y1_mm = region[3];
  grid.width = static_cast<int>(std::floor((region[2] - region[0]) / grid.pitch_mm + 1e-9));
  grid.height = static_cast<int>(std::floor((region[3] - region[1]) / grid.pitch_mm + 1e-9));
  if (grid.width < 1 || grid.height < 1) {
    throw InputError(manifest_file, "/output", "a region of at least one pixel at the chosen dpi");
  }
  return grid;
}

namespace {

// The map of `camera` onto `grid`, each grid pixel centre at height z_mm(col, row) (mm, world).
// The pre-filter strength is taken at the grid's centre, at height z_centre_mm.
template <typename HeightAt>
RectificationMap BuildMapAtHeights(const CameraModel& camera, const MetricGrid& grid, const HeightAt& z_mm,
                                   double z_centre_mm) {
  RectificationMap result;
  result.grid = grid;
  result.map = Image(grid.width, grid.height, 2, 0.0f, grid.pitch_mm);
  result.out_of_view.assign(static_cast<std::size_t>(grid.width) * grid.height, 0);
  ParallelFor(grid.height, [&](std::size_t begin, std::size_t end) {
    for (std::size_t row = begin; row < end; ++row) {
      for (int col = 0; col < grid.width; ++col) {
        bool in_front = false;
        const int r = static_cast<int>(row);
        const Eigen::Vector2d pixel = camera.Project(grid.PixelCentreInWorld(col, r, z_mm(col, r)), &in_front);
        result.map.at(0, r, col) = static_cast<float>(pixel.x());
        result.map.at(1, r, col) = static_cast<float>(pixel.y());
        const bool inside = in_front && pixel.x() >= 0.0 && pixel.y() >= 0.0 && pixel.x() <= camera.width - 1.0 &&
                            pixel.y() <= camera.height - 1.0;
        result.out_of_view[row * grid.width + col] = inside ? 0 : 1;
      }
    }
  });
  const Eigen::Vector3d centre = grid.PixelCentreInWorld(grid.width / 2, grid.height / 2, z_centre_mm);
  const double camera_pitch = camera.PitchOnPlaneMm(centre);
  result.camera_px_per_grid_px = camera_pitch > 0.0 ? grid.pitch_mm / camera_pitch : 1.0;
  return result;
}

}  // namespace

RectificationMap BuildRectificationMap(const CameraModel& camera, const MetricGrid& grid, double height_mm) {
  RectificationMap result = BuildMapAtHeights(camera, grid, [height_mm](int, int) { return height_mm; }, height_mm);
  result.crop_and_scale =
      !camera.HasDistortion() && (camera.pose.rotation - LookingStraightDownRotation()).cwiseAbs().maxCoeff() < 1e-9;
  return result;
}

RectificationMap BuildRectificationMap(const CameraModel& camera, const MetricGrid& grid, const Image& surface_z_mm) {
  if (surface_z_mm.width() != grid.width || surface_z_mm.height() != grid.height || surface_z_mm.channels() != 1) {
    throw std::invalid_argument("BuildRectificationMap: the surface heights must be one plane of the grid's size");
  }
  const double centre_z = surface_z_mm.at(0, grid.height / 2, grid.width / 2);
  return BuildMapAtHeights(
      camera, grid, [&surface_z_mm](int col, int row) { return static_cast<double>(surface_z_mm.at(0, row, col)); },
      centre_z);
}

namespace {

int CvInterpolation(RectifyInterpolation interpolation) {
  switch (interpolation) {
    case RectifyInterpolation::kLinear: return cv::INTER_LINEAR;
    case RectifyInterpolation::kCubic: return cv::INTER_CUBIC;
    case RectifyInterpolation::kLanczos4: return cv::INTER_LANCZOS4;
  }
  return cv::INTER_LINEAR;
}

// Camera pixels a kernel reaches beyond the 2x2 of bilinear interpolation, on each side.
int KernelReach(RectifyInterpolation interpolation) {
  switch (interpolation) {
    case RectifyInterpolation::kLinear: return 0;
    case RectifyInterpolation::kCubic: return 1;
    case RectifyInterpolation::kLanczos4: return 3;
  }
  return 0;
}

// Integral of the unit tent max(0, 1 - |x|) from -inf to x.
double TentIntegral(double x) {
  if (x <= -1.0) return 0.0;
  if (x <= 0.0) return 0.5 * (x + 1.0) * (x + 1.0);
  if (x < 1.0) return 1.0 - 0.5 * (1.0 - x) * (1.0 - x);
  return 1.0;
}

// Below this box width (camera px) the filter is the identity to within 1e-4 per tap.
constexpr double kMinBoxWidthPx = 1e-3;

double BoxWidthPx(double camera_px_per_grid_px) {
  const double s = camera_px_per_grid_px;
  return s > 1.0 ? std::sqrt(s * s - 1.0) : 0.0;
}

void RemapPlane(const cv::Mat& source, cv::Mat destination, const RectificationMap& map, RectifyInterpolation interpolation) {
  const cv::Mat map_x = internal::PlaneView(map.map, 0), map_y = internal::PlaneView(map.map, 1);
  const std::vector<float> taps = FootprintPrefilterKernel(map.camera_px_per_grid_px);
  cv::Mat filtered;
  if (taps.size() > 1) {
    const cv::Mat kernel(1, static_cast<int>(taps.size()), CV_32F, const_cast<float*>(taps.data()));
    cv::sepFilter2D(source, filtered, CV_32F, kernel, kernel, cv::Point(-1, -1), 0.0, cv::BORDER_REFLECT);
  }
  const cv::Mat& input = taps.size() > 1 ? filtered : source;
  if (interpolation == RectifyInterpolation::kLinear) {
    // In-view grid pixels ([0, W-1] x [0, H-1]) never reach beyond the frame with bilinear weights.
    cv::remap(input, destination, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
    return;
  }
  // Wider kernels reach past the frame's edge from in-view pixels: repeat the edge there, and
  // clamp the ringing at 0.
  cv::remap(input, destination, map_x, map_y, CvInterpolation(interpolation), cv::BORDER_REPLICATE);
  cv::max(destination, 0.0, destination);
}

}  // namespace

std::vector<float> FootprintPrefilterKernel(double camera_px_per_grid_px) {
  const double w = BoxWidthPx(camera_px_per_grid_px);
  if (!(w >= kMinBoxWidthPx)) return {1.0f};
  // Tap q: the mean over x in [-w/2, w/2] of the tent centred on q (the image between camera pixel
  // centres is the linear interpolation of their values).
  const int reach = FootprintPrefilterReach(camera_px_per_grid_px);
  std::vector<float> taps(static_cast<std::size_t>(2 * reach + 1));
  double sum = 0.0;
  for (int q = -reach; q <= reach; ++q) {
    const double t = (TentIntegral(q + 0.5 * w) - TentIntegral(q - 0.5 * w)) / w;
    taps[static_cast<std::size_t>(q + reach)] = static_cast<float>(t);
    sum += t;
  }
  for (float& t : taps) t = static_cast<float>(t / sum);
  return taps;
}

int FootprintPrefilterReach(double camera_px_per_grid_px) {
  const double w = BoxWidthPx(camera_px_per_grid_px);
  if (!(w >= kMinBoxWidthPx)) return 0;
  // The tent centred on q overlaps [-w/2, w/2] while |q| < 1 + w/2.
  return static_cast<int>(std::ceil(1.0 + 0.5 * w)) - 1;
}

Image RectifyImage(const Image& image, const RectificationMap& map) {
  Image out(map.grid.width, map.grid.height, image.channels(), 0.0f, map.grid.pitch_mm);
  for (int c = 0; c < image.channels(); ++c) {
    RemapPlane(internal::PlaneView(image, c), internal::PlaneView(out, c), map, map.interpolation);
  }
  return out;
}

RectifiedFrame Rectify(const DecodedFrame& frame, const RectificationMap& map) {
  RectifiedFrame result;
  result.rgb = RectifyImage(frame.rgb, map);
  result.flags.assign(map.out_of_view.size(), 0);
  for (std::size_t i = 0; i < result.flags.size(); ++i) {
    if (map.out_of_view[i]) result.flags[i] |= kOutOfView;
  }
  if (!frame.saturated.empty()) {
    // A grid pixel is saturated when any camera pixel it draws on is (linear weights > 0).
    cv::Mat saturated(frame.rgb.height(), frame.rgb.width(), CV_8U, const_cast<std::uint8_t*>(frame.saturated.data()));
    cv::Mat saturated_f;
    saturated.convertTo(saturated_f, CV_32F);
    // Wider kernels: grow the mask by their extra reach, then the bilinear footprint finds it.
    if (const int reach = KernelReach(map.interpolation); reach > 0) {
      cv::dilate(saturated_f, saturated_f, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * reach + 1, 2 * reach + 1)));
    }
    cv::Mat on_grid(map.grid.height, map.grid.width, CV_32F);
    RemapPlane(saturated_f, on_grid, map, RectifyInterpolation::kLinear);
    for (int row = 0; row < on_grid.rows; ++row) {
      const float* s = on_grid.ptr<float>(row);
      for (int col = 0; col < on_grid.cols; ++col) {
        if (s[col] > 1e-4f) result.flags[static_cast<std::size_t>(row) * on_grid.cols + col] |= kSaturated;
      }
    }
  }
  return result;
}

}  // namespace u3mscan
