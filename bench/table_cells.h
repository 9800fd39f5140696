#pragma once
// Cells of the benchmark's CSV and markdown tables.

#include <string>

namespace u3mscan::bench {

// `v` with `digits` decimals; "" when it is not finite (a figure a row does not have).
std::string Fixed(double v, int digits);

// A CSV field: as it is, or quoted (quotes doubled) when it holds a comma, a quote or a newline.
std::string Csv(const std::string& text);

}  // namespace u3mscan::bench
