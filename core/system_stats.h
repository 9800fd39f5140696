#pragma once
// Process statistics the reports and the benchmark quote: measured, never estimated.

#include <cstdint>

namespace u3mscan {

// Peak resident set size of this process so far (Linux VmHWM), bytes; 0 where unknown.
std::uint64_t PeakResidentBytes();

}  // namespace u3mscan
