#include "capture/stack_builder.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <stdexcept>
#include <string>

#include "capture/rectification.h"
#include "core/error.h"
#include "core/parallel.h"

namespace u3mscan {
namespace {

// DarkAmbient::Apply on rows [y0, y0 + frame rows) of a camera frame (same arithmetic, so the
// result equals the same rows of the corrected whole frame).
void ApplyDarkAmbientRows(const DarkAmbient& dark_ambient, const FrameSpec& spec, int camera_height, int y0,
                          Image& frame) {
  auto subtract = [&](const Image& full, double weight) {
    if (full.width() != frame.width() || full.height() != camera_height || full.channels() != frame.channels()) return;
    const std::size_t w = static_cast<std::size_t>(frame.width()), rows = static_cast<std::size_t>(frame.height());
    for (int c = 0; c < frame.channels(); ++c) {
      const float* f = full.plane(c).data() + static_cast<std::size_t>(y0) * w;
      float* s = frame.data().data() + static_cast<std::size_t>(c) * rows * w;
      for (std::size_t i = 0; i < rows * w; ++i) s[i] += static_cast<float>(weight * f[i]);
    }
  };
  if (const auto dark = dark_ambient.dark_by_camera.find(spec.camera); dark != dark_ambient.dark_by_camera.end()) {
    subtract(dark->second, -1.0);
  }
  if (spec.role != FrameRole::kSample) return;
  if (const auto ambient = dark_ambient.ambient_rate_by_camera_side.find({spec.camera, spec.side});
      ambient != dark_ambient.ambient_rate_by_camera_side.end()) {
    subtract(ambient->second, -spec.exposure_s);
  }
}

// The camera rows a band must read beyond those its map points at: the footprint pre-filter's
// reach (rectification.h), the second bilinear tap, and a row of slack for rounding.
int FilterMarginRows(double camera_px_per_grid_px) {
  constexpr int kBilinearAndRounding = 2;
  return FootprintPrefilterReach(camera_px_per_grid_px) + kBilinearAndRounding + 1;
}

struct BandMap {
  RectificationMap map;  // on the band's grid, camera y relative to y0
  int y0 = 0, rows = 0;  // camera rows to read
};

// `band_z_mm`: empty (the plane z = surface_z_mm) or the band's rows of the relief; `centre_z_mm`:
// the height of the whole grid's centre pixel, where BuildStack measures the pre-filter strength.
BandMap MakeBandMap(const CameraModel& camera, const MetricGrid& full, const MetricGrid& band, double surface_z_mm,
                    const Image& band_z_mm, double centre_z_mm) {
  BandMap out;
  out.map = band_z_mm.empty() ? BuildRectificationMap(camera, band, surface_z_mm)
                              : BuildRectificationMap(camera, band, band_z_mm);
  // The pre-filter strength is the whole grid's (measured at its centre), as in BuildStack.
  const Eigen::Vector3d centre = full.PixelCentreInWorld(full.width / 2, full.height / 2, centre_z_mm);
  const double camera_pitch = camera.PitchOnPlaneMm(centre);
  out.map.camera_px_per_grid_px = camera_pitch > 0.0 ? full.pitch_mm / camera_pitch : 1.0;
  float lo = static_cast<float>(camera.height - 1), hi = 0.0f;
  for (float y : out.map.map.plane(1)) {
    if (!std::isfinite(y)) continue;
    const float c = std::clamp(y, 0.0f, static_cast<float>(camera.height - 1));
    lo = std::min(lo, c), hi = std::max(hi, c);
  }
  if (hi < lo) lo = hi = 0.0f;
  const int margin = FilterMarginRows(out.map.camera_px_per_grid_px);
  out.y0 = std::max(0, static_cast<int>(std::floor(lo)) - margin);
  const int y1 = std::min(camera.height, static_cast<int>(std::ceil(hi)) + margin + 1);
  out.rows = std::max(1, y1 - out.y0);
  // Integer shift: exact in float, and cv::remap's fixed-point fraction is unchanged.
  auto ys = out.map.map.data().begin() + static_cast<std::ptrdiff_t>(out.map.map.pixel_count());
  for (auto it = ys; it != out.map.map.data().end(); ++it) *it -= static_cast<float>(out.y0);
  return out;
}

}  // namespace

MetricGrid GridRows(const MetricGrid& grid, int row0, int rows) {
  if (row0 < 0 || rows <= 0 || row0 + rows > grid.height) {
    throw std::out_of_range("GridRows: rows [" + std::to_string(row0) + ", " + std::to_string(row0 + rows) +
                            ") outside a grid of " + std::to_string(grid.height) + " rows");
  }
  MetricGrid band = grid;
  band.height = rows;
  band.y1_mm = grid.y1_mm - row0 * grid.pitch_mm;
  return band;
}

std::vector<std::size_t> SideSampleFrames(const Manifest& manifest, const std::string& side) {
  std::vector<std::size_t> out;
  for (std::size_t i = 0; i < manifest.frames.size(); ++i) {
    if (manifest.frames[i].role == FrameRole::kSample && manifest.frames[i].side == side) out.push_back(i);
  }
  return out;
}

void NormaliseObservationRgb(Image& rgb, double exposure_s, const Eigen::Vector3d& intensity_rgb, bool colour,
                             const Eigen::Matrix3f& colour_matrix) {
  const Eigen::Vector3d scale = (exposure_s * intensity_rgb).cwiseInverse();
  ParallelFor(rgb.pixel_count(), [&](std::size_t begin, std::size_t end) {
    float* r = rgb.plane(0).data();
    float* g = rgb.plane(1).data();
    float* b = rgb.plane(2).data();
    for (std::size_t i = begin; i < end; ++i) {
      Eigen::Vector3f v(static_cast<float>(r[i] * scale[0]), static_cast<float>(g[i] * scale[1]),
                        static_cast<float>(b[i] * scale[2]));
      if (colour) v = colour_matrix * v;
      r[i] = v[0], g[i] = v[1], b[i] = v[2];
    }
  });
}

Stack BuildStackRows(const Capture& capture, const CalibrationResult& calibration, const CalibrationOptions& options,
                     const std::vector<std::size_t>& frames, int row0, int rows, const ProgressCallback& progress,
                     const Image& surface_z_mm) {
  const Manifest& manifest = capture.manifest();
  Stack stack;
  stack.side = options.side;
  stack.grid = GridRows(calibration.grid, row0, rows);
  const MetricGrid& full = calibration.grid;
  if (!surface_z_mm.empty() &&
      (surface_z_mm.width() != full.width || surface_z_mm.height() != full.height || surface_z_mm.channels() != 1)) {
    throw std::invalid_argument("BuildStackRows: the surface heights must be one plane of the whole grid's size");
  }
  const Image band_z = surface_z_mm.empty() ? Image() : CropRows(surface_z_mm, row0, rows);
  const double centre_z =
      surface_z_mm.empty() ? calibration.surface_z_mm : surface_z_mm.at(0, full.height / 2, full.width / 2);
  std::map<std::string, int> view_of_camera, light_of_id;
  std::map<std::string, BandMap> maps;
  const bool colour = options.apply_colour_correction && calibration.colour.applied;
  const Eigen::Matrix3f colour_matrix = calibration.colour.fit.matrix.cast<float>();
  for (std::size_t n = 0; n < frames.size(); ++n) {
    const std::size_t index = frames[n];
    const FrameSpec& spec = manifest.frames.at(index);
    const CameraCalibration* camera = calibration.FindCamera(spec.camera);
    const LightCalibration* light = spec.light ? calibration.FindLight(*spec.light) : nullptr;
    if (spec.role != FrameRole::kSample || spec.side != options.side || !camera || !light) {
      throw InputError(spec.file, "/frames/" + std::to_string(index),
                       "a sample frame of side " + options.side + " of a calibrated camera under one light");
    }
    if (!view_of_camera.count(spec.camera)) {
      view_of_camera[spec.camera] = static_cast<int>(stack.views.size());
      stack.views.push_back({spec.camera, camera->model.CentreInWorld()});
      maps.emplace(spec.camera,
                   MakeBandMap(camera->model, full, stack.grid, calibration.surface_z_mm, band_z, centre_z));
    }
    if (!light_of_id.count(*spec.light)) {
      light_of_id[*spec.light] = static_cast<int>(stack.lights.size());
      stack.lights.push_back(light->model);
    }
    const BandMap& band = maps.at(spec.camera);
    DecodedFrame frame = capture.LoadFrameRows(index, band.y0, band.rows);
    ApplyDarkAmbientRows(calibration.dark_ambient, spec, camera->model.height, band.y0, frame.rgb);
    RectifiedFrame rectified = Rectify(frame, band.map);
    NormaliseObservationRgb(rectified.rgb, spec.exposure_s, light->model.intensity_rgb, colour, colour_matrix);
    Observation observation;
    observation.view = view_of_camera[spec.camera];
    observation.light = light_of_id[*spec.light];
    observation.rgb = std::move(rectified.rgb);
    observation.flags = std::move(rectified.flags);
    if (const FlatCalibration* flat = calibration.FindFlat(spec.camera, *spec.light, spec.side)) {
      observation.irradiance = CropRows(flat->irradiance, row0, rows);
    }
    stack.observations.push_back(std::move(observation));
    ReportProgress(progress, "stack", static_cast<double>(n + 1) / frames.size());
  }
  return stack;
}

}  // namespace u3mscan
