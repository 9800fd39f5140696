#pragma once
// Wall-clock time of a stage, for the run times the reports print: the steady clock (it never jumps
// with the system clock), in seconds. One style everywhere: `const double start = SteadySeconds();`
// when the stage begins, `SteadySeconds() - start` when it ends.

#include <chrono>

namespace u3mscan {

// The steady clock's reading in seconds: only differences of two readings mean anything.
inline double SteadySeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

}  // namespace u3mscan
