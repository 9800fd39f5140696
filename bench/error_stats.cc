#include "bench/error_stats.h"

#include <algorithm>
#include <cmath>
#include <cstddef>

namespace u3mscan::bench {

ErrorStats Summarise(std::vector<float> values) {
  values.erase(std::remove_if(values.begin(), values.end(), [](float v) { return !std::isfinite(v); }), values.end());
  ErrorStats s;
  if (values.empty()) return s;
  double sum = 0;
  for (float v : values) sum += v;
  s.mean = sum / static_cast<double>(values.size());
  auto rank = [&](double q) {
    const std::size_t k = std::min(values.size() - 1, static_cast<std::size_t>(std::ceil(q * values.size())) - (q > 0 ? 1 : 0));
    std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
    return static_cast<double>(values[k]);
  };
  s.median = rank(0.5);
  s.p95 = rank(0.95);
  return s;
}

}  // namespace u3mscan::bench
