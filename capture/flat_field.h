#pragma once
// Flat field: the per-pixel irradiance of each light on the metric grid.
//
// A `flat` frame shows a white target of known reflectance rho at the sample plane under one light.
// After dark subtraction, a Lambertian target reads (capture contract, "Grids and radiometry")
//   v_c = exposure_s * (rho / pi) * cos(theta_i) * intensity_c * E_rel * vignetting
// so the measured relative irradiance (units of LightModel::RelativeIrradianceAt, 1/mm^2 for a
// point light, 1 for a directional one) is
//   E_meas = mean_c( pi * v_c / (exposure_s * intensity_c * rho * cos(theta_i)) ).
// It holds the emitter's true profile, the inverse-square falloff and the lens vignetting at once;
// dividing a sample frame by it (with the same cosine) divides all three out. Without flat frames
// the analytic model of the manifest (inverse square, cos^n profile) is used and vignetting is not
// corrected.

#include <string>

#include "capture/manifest.h"
#include "core/image.h"
#include "core/stack.h"

namespace u3mscan {

// E_meas on the grid from a rectified, dark-subtracted flat frame (3 channels, frame units).
// Pixels where the light grazes the target (cos < min_cos) or the reading is not positive get 0.
Image MeasuredIrradiance(const Image& flat_on_grid, const FrameSpec& flat_spec, const LightModel& light,
                         const MetricGrid& grid, double reflectance, double min_cos = 0.05);

// The analytic relative irradiance of `light` on the grid (plane z = height_mm), 1 channel.
Image AnalyticIrradiance(const LightModel& light, const MetricGrid& grid, double height_mm = 0.0);

// A flat frame must be brighter than the sample frames it corrects (a white target reflects more
// than fabric): compares the median rates (value per second of exposure) of the two frames over
// the pixels `valid` marks (empty = all). Throws InputError naming the flat frame (field
// /frames/<flat_index>) when it is darker.
void CheckFlatBrighterThanSample(const Image& flat, const FrameSpec& flat_spec, std::size_t flat_index,
                                 const Image& sample, const FrameSpec& sample_spec);

// Uniformity of an image region: (max - min) / mean over the pixels with value > 0 (1 channel),
// the figure the flat-field test judges.
double NonUniformity(const Image& image, int channel = 0);

}  // namespace u3mscan
