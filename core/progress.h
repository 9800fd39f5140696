#pragma once
// Progress: libraries report (stage, fraction done) through a callback; only the CLI draws a bar.

#include <functional>
#include <string_view>

namespace u3mscan {

// stage: short name ("decode", "photometric stereo"); fraction: 0..1 of that stage.
using ProgressCallback = std::function<void(std::string_view stage, double fraction)>;

// Calls `callback` if set; a convenience so stages need no null checks.
inline void ReportProgress(const ProgressCallback& callback, std::string_view stage, double fraction) {
  if (callback) callback(stage, fraction);
}

}  // namespace u3mscan
