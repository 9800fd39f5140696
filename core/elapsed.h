#pragma once
// Wall-clock time of a stage, for the run times the reports print: the steady clock (it never jumps
// with the system clock), in seconds.

#include <chrono>

namespace u3mscan {

using SteadyClock = std::chrono::steady_clock;

// The steady clock's reading in seconds: only differences of two readings mean anything (a stage's
// seconds = SteadySeconds() at its end - SteadySeconds() at its start).
inline double SteadySeconds() { return std::chrono::duration<double>(SteadyClock::now().time_since_epoch()).count(); }

// Seconds from `start` (SteadyClock::now() taken when the stage began) to now.
inline double SecondsSince(SteadyClock::time_point start) {
  return std::chrono::duration<double>(SteadyClock::now() - start).count();
}

}  // namespace u3mscan
