#include "cli/progress_bar.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/logging.h"

namespace u3mscan::cli {

ProgressBar::ProgressBar(bool quiet, std::string prefix)
    : quiet_(quiet), terminal_(isatty(fileno(stderr)) != 0), prefix_(std::move(prefix)) {}

ProgressBar::~ProgressBar() { Finish(); }

ProgressCallback ProgressBar::Callback() {
  return [this](std::string_view stage, double fraction) { Update(stage, fraction); };
}

void ProgressBar::Update(std::string_view stage, double fraction) {
  if (quiet_) return;
  std::lock_guard lock(mutex_);
  fraction = std::clamp(fraction, 0.0, 1.0);
  const auto now = Clock::now();
  if (stage != stage_) {
    stage_ = stage;
    stage_start_ = now;
    last_quarter_ = -1;
  }
  const double elapsed_s = std::chrono::duration<double>(now - stage_start_).count();
  if (terminal_) {
    constexpr int kWidth = 30;
    const int filled = static_cast<int>(std::lround(fraction * kWidth));
    std::string bar(filled, '#');
    bar.append(kWidth - filled, '-');
    std::string eta;
    if (fraction > 0.02 && fraction < 1.0) {
      eta = "  " + std::to_string(static_cast<int>(std::ceil(elapsed_s * (1.0 - fraction) / fraction))) + " s left";
    }
    std::fprintf(stderr, "\r\033[K%s[%s] %s %3d%%%s", prefix_.c_str(), stage_.c_str(), bar.c_str(),
                 static_cast<int>(std::lround(fraction * 100)), eta.c_str());
    std::fflush(stderr);
    line_open_ = true;
  } else {
    const int quarter = static_cast<int>(fraction * 4.0);
    if (quarter != last_quarter_) {
      last_quarter_ = quarter;
      LogInfo() << prefix_ << stage_ << ": " << quarter * 25 << "%";
    }
  }
}

void ProgressBar::Finish() {
  std::lock_guard lock(mutex_);
  if (line_open_) {
    std::fprintf(stderr, "\n");
    line_open_ = false;
  }
}

}  // namespace u3mscan::cli
