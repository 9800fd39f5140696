#pragma once
// Units: the pipeline works in millimetres, degrees at the edges (files, CLI) and radians inside,
// seconds. These helpers make every conversion explicit and named.

#include <numbers>

namespace u3mscan {

inline constexpr double kPi = std::numbers::pi;
inline constexpr double kMmPerInch = 25.4;
inline constexpr double kMmPerCm = 10.0;

constexpr double DegToRad(double angle_deg) { return angle_deg * kPi / 180.0; }
constexpr double RadToDeg(double angle_rad) { return angle_rad * 180.0 / kPi; }

// Pixel pitch on the sample plane (mm per pixel) <-> dots per inch.
constexpr double DpiToPitchMm(double dpi) { return kMmPerInch / dpi; }
constexpr double PitchMmToDpi(double pitch_mm) { return kMmPerInch / pitch_mm; }

}  // namespace u3mscan
