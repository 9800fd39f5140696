#include "pipeline/alpha_map.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace u3mscan {

AlphaEstimate AlphaFromBacklight(const Image& transmitted, const std::vector<std::uint8_t>& flags) {
  AlphaEstimate estimate;
  const std::size_t n = transmitted.pixel_count();
  std::vector<float> luminance(n);
  float hi = 0.0f;
  for (std::size_t i = 0; i < n; ++i) {
    float y = transmitted.plane(0)[i];
    if (transmitted.channels() >= 3) {
      y = 0.2126f * transmitted.plane(0)[i] + 0.7152f * transmitted.plane(1)[i] + 0.0722f * transmitted.plane(2)[i];
    }
    luminance[i] = std::isfinite(y) ? std::max(0.0f, y) : 0.0f;
    const bool usable = flags.empty() || flags[i] == 0;
    if (usable) hi = std::max(hi, luminance[i]);
  }
  if (!(hi > 0.0f)) {
    estimate.note = "the backlight frame is black: no light passes the sample";
    return estimate;
  }

  // Otsu's threshold on a 256-bin histogram of usable pixels.
  constexpr int kBins = 256;
  std::array<double, kBins> count{}, sum{};
  double total = 0.0, total_sum = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!flags.empty() && flags[i] != 0) continue;
    const int bin = std::min(kBins - 1, static_cast<int>(luminance[i] / hi * kBins));
    count[bin] += 1.0;
    sum[bin] += luminance[i];
    total += 1.0;
    total_sum += luminance[i];
  }
  double best_score = -1.0, w0 = 0.0, s0 = 0.0;
  int best_bin = 0;
  for (int b = 0; b < kBins - 1; ++b) {
    w0 += count[b];
    s0 += sum[b];
    const double w1 = total - w0;
    if (w0 <= 0.0 || w1 <= 0.0) continue;
    const double m0 = s0 / w0, m1 = (total_sum - s0) / w1;
    const double score = w0 * w1 * (m1 - m0) * (m1 - m0);
    if (score > best_score) {
      best_score = score;
      best_bin = b;
    }
  }
  double c0 = 0.0, c1 = 0.0, n0 = 0.0, n1 = 0.0;
  for (int b = 0; b < kBins; ++b) {
    if (b <= best_bin) {
      c0 += sum[b];
      n0 += count[b];
    } else {
      c1 += sum[b];
      n1 += count[b];
    }
  }
  estimate.fabric_level = n0 > 0 ? c0 / n0 : 0.0;
  estimate.open_level = n1 > 0 ? c1 / n1 : 0.0;
  const double open_fraction = total > 0 ? n1 / total : 0.0;
  if (n1 <= 0.0 || estimate.open_level < kMinContrast * estimate.fabric_level || open_fraction < kMinHoleFraction) {
    estimate.note = "no holes: the backlight shows no open areas clearly brighter than the fabric";
    return estimate;
  }

  estimate.alpha = Image(transmitted.width(), transmitted.height(), 1, 1.0f, transmitted.pitch_mm());
  auto alpha = estimate.alpha.plane(0);
  const double span = estimate.open_level - estimate.fabric_level;
  std::size_t open = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double t = (luminance[i] - estimate.fabric_level) / span;
    alpha[i] = static_cast<float>(1.0 - std::clamp((t - 0.25) / 0.5, 0.0, 1.0));
    open += alpha[i] < 0.5f;
  }
  estimate.hole_fraction = n ? static_cast<double>(open) / static_cast<double>(n) : 0.0;
  return estimate;
}

}  // namespace u3mscan
