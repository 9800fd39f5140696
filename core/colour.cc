#include "core/colour.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "core/principled_brdf.h"

namespace u3mscan {

double SrgbToLinear(double encoded) {
  if (encoded <= 0.04045) return encoded / 12.92;
  return std::pow((encoded + 0.055) / 1.055, 2.4);
}

double LinearToSrgb(double linear) {
  linear = std::clamp(linear, 0.0, 1.0);
  if (linear <= 0.0031308) return 12.92 * linear;
  return 1.055 * std::pow(linear, 1.0 / 2.4) - 0.055;
}

float SrgbToLinear(float encoded) { return static_cast<float>(SrgbToLinear(double{encoded})); }
float LinearToSrgb(float linear) { return static_cast<float>(LinearToSrgb(double{linear})); }

Lab LinearSrgbToLab(const Rgb& c) {
  // IEC 61966-2-1 matrix, D65 white normalised to Y = 1.
  const double x = 0.4124564 * c[0] + 0.3575761 * c[1] + 0.1804375 * c[2];
  const double y = 0.2126729 * c[0] + 0.7151522 * c[1] + 0.0721750 * c[2];
  const double z = 0.0193339 * c[0] + 0.1191920 * c[1] + 0.9503041 * c[2];
  constexpr double kXn = 0.95047, kYn = 1.0, kZn = 1.08883;
  auto f = [](double t) {
    constexpr double kDelta = 6.0 / 29.0;
    return t > kDelta * kDelta * kDelta ? std::cbrt(t) : t / (3 * kDelta * kDelta) + 4.0 / 29.0;
  };
  const double fx = f(x / kXn), fy = f(y / kYn), fz = f(z / kZn);
  return {116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)};
}

double Ciede2000(const Lab& lab1, const Lab& lab2) {
  using std::atan2, std::cos, std::exp, std::fabs, std::pow, std::sin, std::sqrt;
  constexpr double kPi = std::numbers::pi;
  auto deg = [](double rad) { return rad * 180.0 / kPi; };
  auto rad = [](double d) { return d * kPi / 180.0; };

  const double c1 = sqrt(lab1[1] * lab1[1] + lab1[2] * lab1[2]);
  const double c2 = sqrt(lab2[1] * lab2[1] + lab2[2] * lab2[2]);
  const double c_bar = 0.5 * (c1 + c2);
  const double c_bar7 = pow(c_bar, 7.0);
  const double g = 0.5 * (1.0 - sqrt(c_bar7 / (c_bar7 + pow(25.0, 7.0))));
  const double a1p = (1.0 + g) * lab1[1], a2p = (1.0 + g) * lab2[1];
  const double c1p = sqrt(a1p * a1p + lab1[2] * lab1[2]);
  const double c2p = sqrt(a2p * a2p + lab2[2] * lab2[2]);
  auto hue = [&](double b, double ap) {
    if (b == 0.0 && ap == 0.0) return 0.0;
    double h = deg(atan2(b, ap));
    return h < 0.0 ? h + 360.0 : h;
  };
  const double h1p = hue(lab1[2], a1p), h2p = hue(lab2[2], a2p);

  const double dLp = lab2[0] - lab1[0];
  const double dCp = c2p - c1p;
  double dhp = 0.0;
  if (c1p * c2p != 0.0) {
    dhp = h2p - h1p;
    if (dhp > 180.0) dhp -= 360.0;
    else if (dhp < -180.0) dhp += 360.0;
  }
  const double dHp = 2.0 * sqrt(c1p * c2p) * sin(rad(dhp) / 2.0);

  const double l_bar = 0.5 * (lab1[0] + lab2[0]);
  const double cp_bar = 0.5 * (c1p + c2p);
  double hp_bar = h1p + h2p;
  if (c1p * c2p != 0.0) {
    if (fabs(h1p - h2p) <= 180.0) hp_bar = 0.5 * (h1p + h2p);
    else if (h1p + h2p < 360.0) hp_bar = 0.5 * (h1p + h2p + 360.0);
    else hp_bar = 0.5 * (h1p + h2p - 360.0);
  }
  const double t = 1.0 - 0.17 * cos(rad(hp_bar - 30.0)) + 0.24 * cos(rad(2.0 * hp_bar)) +
                   0.32 * cos(rad(3.0 * hp_bar + 6.0)) - 0.20 * cos(rad(4.0 * hp_bar - 63.0));
  const double d_theta = 30.0 * exp(-pow((hp_bar - 275.0) / 25.0, 2.0));
  const double cp_bar7 = pow(cp_bar, 7.0);
  const double rc = 2.0 * sqrt(cp_bar7 / (cp_bar7 + pow(25.0, 7.0)));
  const double l50 = (l_bar - 50.0) * (l_bar - 50.0);
  const double sl = 1.0 + 0.015 * l50 / sqrt(20.0 + l50);
  const double sc = 1.0 + 0.045 * cp_bar;
  const double sh = 1.0 + 0.015 * cp_bar * t;
  const double rt = -sin(rad(2.0 * d_theta)) * rc;
  const double tl = dLp / sl, tc = dCp / sc, th = dHp / sh;
  return sqrt(tl * tl + tc * tc + th * th + rt * tc * th);
}

double PrincipledLuminance(const Rgb& c) { return brdf::kTintLumR * c[0] + brdf::kTintLumG * c[1] + brdf::kTintLumB * c[2]; }

}  // namespace u3mscan
