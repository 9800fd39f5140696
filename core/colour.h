#pragma once
// Colour: sRGB transfer function (IEC 61966-2-1) and CIE colour differences.
// All maths in the pipeline happens in linear RGB with sRGB/Rec.709 primaries and D65 white.

#include <array>

namespace u3mscan {

// sRGB-encoded value (0..1) -> linear (0..1). Exact piecewise curve, not a 2.2 gamma.
double SrgbToLinear(double encoded);
// Linear (0..1) -> sRGB-encoded (0..1). Values outside 0..1 are clamped first.
double LinearToSrgb(double linear);
float SrgbToLinear(float encoded);
float LinearToSrgb(float linear);

using Rgb = std::array<double, 3>;
using Lab = std::array<double, 3>;

// Linear sRGB (D65) -> CIE XYZ (Y of white = 1) -> CIELAB relative to D65.
Lab LinearSrgbToLab(const Rgb& linear_rgb);
// CIEDE2000 colour difference (Sharma, Wu, Dalal 2005), kL = kC = kH = 1.
double Ciede2000(const Lab& a, const Lab& b);

// Relative luminance with the weights of the Principled BRDF's tint (core/principled_brdf.h,
// brdf::TintLuminance; docs/principled-brdf.md):
// lum = 0.3 R + 0.6 G + 0.1 B. Not Rec.709 luminance; kept as Disney wrote it.
double PrincipledLuminance(const Rgb& linear_rgb);

}  // namespace u3mscan
