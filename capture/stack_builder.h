#pragma once
// Stacks of a band of rows of the metric grid, for scans whose whole stack does not fit in memory
// (docs/process.md, "Large scans: memory and time").
//
// A band of rows [row0, row0 + rows) of the calibration's grid is again a MetricGrid (same pitch
// and x0_mm, top edge y1_mm - row0 * pitch), so every stage that takes a Stack takes a band. For
// each sample frame only the camera rows the band's rectification map draws on (plus the margin
// of the bilinear taps and the anti-aliasing pre-filter) are read (Capture::LoadFrameRows; RAW
// frames go through the Capture's bounded decode cache), so a band costs its own rows, not whole
// frames. The observations are bit-identical to the same rows of BuildStack's (tested).

#include <cstddef>
#include <vector>

#include "capture/calibrate.h"
#include "capture/capture.h"
#include "core/progress.h"
#include "core/stack.h"

namespace u3mscan {

// Rows [row0, row0 + rows) of `grid` as a grid of their own.
MetricGrid GridRows(const MetricGrid& grid, int row0, int rows);

// The sample frames (manifest indices) BuildStack uses for options.side, in its order.
std::vector<std::size_t> SideSampleFrames(const Manifest& manifest, const std::string& side);

// The band [row0, row0 + rows) of calibration.grid as BuildStack would give its rows, built from
// `frames` only (manifest indices of sample frames of options.side; views and lights are numbered in
// that order, as BuildStack numbers them). `surface_z_mm` as BuildStack's: empty (the plane
// calibration.surface_z_mm) or the heights of the WHOLE grid (1 plane, mm, world z), of which the
// band takes its rows. Throws InputError like BuildStack, std::out_of_range for rows outside the
// grid, std::invalid_argument for heights of another size.
Stack BuildStackRows(const Capture& capture, const CalibrationResult& calibration, const CalibrationOptions& options,
                     const std::vector<std::size_t>& frames, int row0, int rows,
                     const ProgressCallback& progress = {}, const Image& surface_z_mm = Image());

// Frame units -> the Stack's units in place (BuildStack and BuildStackRows): divide by exposure and
// the light's intensity per channel, then apply the colour matrix when `colour` is set.
void NormaliseObservationRgb(Image& rgb, double exposure_s, const Eigen::Vector3d& intensity_rgb, bool colour,
                             const Eigen::Matrix3f& colour_matrix);

}  // namespace u3mscan
