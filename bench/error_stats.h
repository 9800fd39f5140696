#pragma once
// Summary statistics of a per-pixel error (angles in degrees, CIEDE2000, ...), as the benchmark
// tables print them.

#include <limits>
#include <vector>

namespace u3mscan::bench {

struct ErrorStats {
  double mean = std::numeric_limits<double>::quiet_NaN();
  double median = std::numeric_limits<double>::quiet_NaN();
  double p95 = std::numeric_limits<double>::quiet_NaN();
};

// Mean, median and 95th percentile (nearest rank) of the finite values; NaN each when there are
// none. Takes its argument by value: the ranks reorder it.
ErrorStats Summarise(std::vector<float> values);

}  // namespace u3mscan::bench
