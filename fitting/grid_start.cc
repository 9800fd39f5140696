#include "fitting/grid_start.h"

#include <limits>
#include <span>

namespace u3mscan::fitting {
namespace {
constexpr double kRoughnessGrid[] = {kSmallestStartRoughness, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.85, 1.0};
constexpr double kSpecularGrid[] = {0.0, 0.25, 0.5, 0.75, 1.0};
constexpr double kSheenGrid[] = {0.0, 0.35, 0.7, 1.0};
constexpr double kNoSheen[] = {0.0};
}  // namespace

ParameterVector GridStart(const ParameterMask& candidates, const ParameterVector& held, bool search_sheen,
                          const std::function<double(const ParameterVector&)>& cost, double min_roughness) {
  ParameterVector start = held;
  for (FitParameter p : {FitParameter::kSpecularTint, FitParameter::kSheenTint, FitParameter::kAnisotropic,
                         FitParameter::kMetallic}) {
    if (candidates[static_cast<int>(p)]) start[static_cast<int>(p)] = 0.0;
  }
  auto grid = [&](int i, std::span<const double> values) {
    return candidates[i] ? values : std::span<const double>(&held[i], 1);
  };
  double best = std::numeric_limits<double>::infinity();
  ParameterVector trial = start;
  for (double r : grid(kRoughness, kRoughnessGrid)) {
    if (candidates[kRoughness] && r < min_roughness) continue;
    for (double s : grid(kSpecular, kSpecularGrid)) {
      for (double sh : grid(kSheen, search_sheen ? std::span<const double>(kSheenGrid) : kNoSheen)) {
        trial[kRoughness] = r;
        trial[kSpecular] = s;
        trial[kSheen] = sh;
        const double c = cost(trial);
        if (c < best) {
          best = c;
          start = trial;
        }
      }
    }
  }
  return start;
}

}  // namespace u3mscan::fitting
