#pragma once
// Rectification: every view (the oblique camera too) is undistorted and resampled onto the metric
// grid of the sample plane (core/stack.h MetricGrid), so that pixel (i, j) of every frame sees the
// same point of the fabric. The map of a camera is computed once from its pose and intrinsics
// (each grid pixel centre projected through the lens) and applied with cv::remap; grid pixels the
// camera does not see, and those that draw on saturated camera pixels, are flagged, never used.

#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include "capture/calibration_frames.h"
#include "capture/camera_model.h"
#include "capture/manifest.h"
#include "core/image.h"
#include "core/stack.h"

namespace u3mscan {

// The grid of the finished maps: `output.dpi` (default: the native resolution of the finest
// camera at the region's centre, rounded down to a whole dpi) over `output.region_mm` (default:
// the largest axis-aligned rectangle every camera sees whole). The grid keeps the region's
// top-left corner; its size is the whole number of pixels that fit. Throws InputError (field
// /output) when the region is empty or the cameras share no view of the plane.
// `surface_z_mm`: the plane the maps lie in, the sample's face (its thickness above the z = 0
// table plane, SampleSurfaceZMm); the default region and resolution are taken there.
MetricGrid ChooseGrid(const std::vector<CameraModel>& cameras, const OutputSpec& output,
                      const std::string& manifest_file = "capture.json", double surface_z_mm = 0.0);

// The rectangle [x0, y0, x1, y1] (mm) of the plane z = surface_z_mm that every camera sees whole.
std::array<double, 4> CommonRegionMm(const std::vector<CameraModel>& cameras, double surface_z_mm = 0.0);

// The plane the sample's face lies in (mm above the z = 0 plane the sample rests on, where the
// board, flats and chart lie): the manifest's sample.thickness_mm, 0 when it is not given. A
// camera D mm above sees a face t mm up at a scale off by t / (D - t) and, when it is tilted by
// theta, shifted by t tan(theta): maps made on z = 0 would be misregistered by that much
// (docs/calibration.md, "Grid").
double SampleSurfaceZMm(const Manifest& manifest);

// How camera pixels are interpolated at a grid pixel's centre (cv::remap). Results are clamped
// at 0 (the ringing of the cubic and Lanczos kernels next to dark edges cannot make light
// negative); the saturation flag covers every camera pixel a kernel reaches.
enum class RectifyInterpolation {
  kLinear,    // bilinear, 2x2 camera pixels
  kCubic,     // bicubic (a = -0.75), 4x4
  kLanczos4,  // Lanczos, 8x8
};
inline constexpr RectifyInterpolation kDefaultRectifyInterpolation = RectifyInterpolation::kCubic;

struct RectificationMap {
  MetricGrid grid;
  Image map;                              // 2 planes: camera x and y (px) of each grid pixel centre
  std::vector<std::uint8_t> out_of_view;  // grid size, 1 = the camera does not see the point
  double camera_px_per_grid_px = 1.0;     // at the grid's centre; > 1 means the grid is coarser
  bool crop_and_scale = false;            // straight-down camera without distortion (an affine map)
  RectifyInterpolation interpolation = kDefaultRectifyInterpolation;
};

// `height_mm`: the plane the map is computed for (the sample's face, SampleSurfaceZMm, for the
// frames of the sample stack; 0 for targets lying on the table).
RectificationMap BuildRectificationMap(const CameraModel& camera, const MetricGrid& grid, double height_mm = 0.0);
// The same with a height per grid pixel (`surface_z_mm`: 1 plane of the grid's size, mm, world z):
// the relief's own parallax taken out, which a tilted view needs (a relief of 0.2 mm seen at 60 deg
// moves by 0.35 mm). Never a crop and scale. Throws std::invalid_argument on a size mismatch.
RectificationMap BuildRectificationMap(const CameraModel& camera, const MetricGrid& grid, const Image& surface_z_mm);

struct RectifiedFrame {
  Image rgb;                          // grid size, pitch_mm = grid pitch
  std::vector<std::uint8_t> flags;    // ObservationFlag bits (kSaturated, kOutOfView)
};

// Footprint pre-filter, applied to the camera image before the interpolation when the grid is
// coarser than the camera (s = camera_px_per_grid_px > 1). A finished map pixel holds the fabric
// averaged over its footprint, s x s camera pixels; a camera pixel has already averaged over 1 x 1.
// The filter is a box of width w = sqrt(s^2 - 1) camera px over the linearly interpolated image
// (separable, the same along rows and columns), so that the camera pixel's spread plus the box's
// equals the footprint's (variances 1/12 + w^2/12 = s^2/12). It keeps the contrast of threads two
// to four grid pixels wide that a Gaussian at the grid's Nyquist limit (sigma = 0.5 sqrt(s^2 - 1),
// three times the variance) blurred away; docs/calibration.md has the measurements.
// Taps q = -reach .. reach, symmetric, summing to 1; {1} (reach 0) for s <= 1.
std::vector<float> FootprintPrefilterKernel(double camera_px_per_grid_px);
int FootprintPrefilterReach(double camera_px_per_grid_px);

// Resamples `frame` (camera pixels) onto the map's grid (map.interpolation, after the footprint
// pre-filter when the grid is coarser than the camera).
RectifiedFrame Rectify(const DecodedFrame& frame, const RectificationMap& map);
// The same for any image (all channels), without flags.
Image RectifyImage(const Image& image, const RectificationMap& map);

}  // namespace u3mscan
