#include "capture/flat_field.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <vector>

#include "core/error.h"
#include "core/parallel.h"
#include "core/units.h"

namespace u3mscan {
namespace {

double MedianRate(const Image& image, double exposure_s) {
  std::vector<float> values;
  values.reserve(image.pixel_count());
  for (std::size_t i = 0; i < image.pixel_count(); ++i) {
    double sum = 0.0;
    for (int c = 0; c < image.channels(); ++c) sum += image.plane(c)[i];
    values.push_back(static_cast<float>(sum / image.channels()));
  }
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2] / exposure_s;
}

}  // namespace

Image MeasuredIrradiance(const Image& flat_on_grid, const FrameSpec& flat_spec, const LightModel& light,
                         const MetricGrid& grid, double reflectance, double min_cos) {
  Image out(grid.width, grid.height, 1, 0.0f, grid.pitch_mm);
  const double scale = kPi / (flat_spec.exposure_s * reflectance);
  ParallelFor(grid.height, [&](std::size_t begin, std::size_t end) {
    for (std::size_t row = begin; row < end; ++row) {
      for (int col = 0; col < grid.width; ++col) {
        const Eigen::Vector3d point = grid.PixelCentreInWorld(col, static_cast<int>(row));
        const double cos_theta = light.DirectionFrom(point).z();  // target normal = +z
        if (cos_theta < min_cos) continue;
        double sum = 0.0;
        for (int c = 0; c < 3; ++c) sum += flat_on_grid.at(c, static_cast<int>(row), col) / light.intensity_rgb[c];
        const double e = scale * sum / 3.0 / cos_theta;
        out.at(0, static_cast<int>(row), col) = e > 0.0 ? static_cast<float>(e) : 0.0f;
      }
    }
  });
  return out;
}

Image AnalyticIrradiance(const LightModel& light, const MetricGrid& grid, double height_mm) {
  Image out(grid.width, grid.height, 1, 0.0f, grid.pitch_mm);
  ParallelFor(grid.height, [&](std::size_t begin, std::size_t end) {
    for (std::size_t row = begin; row < end; ++row) {
      for (int col = 0; col < grid.width; ++col) {
        out.at(0, static_cast<int>(row), col) = static_cast<float>(
            light.RelativeIrradianceAt(grid.PixelCentreInWorld(col, static_cast<int>(row), height_mm)));
      }
    }
  });
  return out;
}

void CheckFlatBrighterThanSample(const Image& flat, const FrameSpec& flat_spec, std::size_t flat_index,
                                 const Image& sample, const FrameSpec& sample_spec) {
  const double flat_rate = MedianRate(flat, flat_spec.exposure_s);
  const double sample_rate = MedianRate(sample, sample_spec.exposure_s);
  if (flat_rate <= sample_rate) {
    std::ostringstream what;
    what << "a flat frame (white target) brighter than its sample frame " << sample_spec.file << " under light "
         << flat_spec.light.value_or("?") << "; its median is " << flat_rate << " per second against "
         << sample_rate << " (wrong file, target missing, or the light was off?)";
    throw InputError(flat_spec.file, "/frames/" + std::to_string(flat_index), what.str());
  }
}

double NonUniformity(const Image& image, int channel) {
  double lo = 1e300, hi = -1e300, sum = 0.0;
  std::size_t n = 0;
  for (float v : image.plane(channel)) {
    if (!(v > 0.0f)) continue;
    lo = std::min(lo, static_cast<double>(v)), hi = std::max(hi, static_cast<double>(v));
    sum += v, ++n;
  }
  return n == 0 ? 0.0 : (hi - lo) / (sum / n);
}

}  // namespace u3mscan
