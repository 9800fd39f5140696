#pragma once
// A number for a JSON report: the value, or null where it is not finite (JSON holds no NaN or Inf:
// the std of a parameter left out is infinite, a figure not measured is NaN).

#include <cmath>
#include <nlohmann/json.hpp>

namespace u3mscan {

template <class Json = nlohmann::json>
Json FiniteOrNull(double value) {
  return std::isfinite(value) ? Json(value) : Json(nullptr);
}

}  // namespace u3mscan
