#pragma once
// ProgressBar: turns the libraries' progress callbacks into a bar on a terminal
// ("[stage] ####----  45%  12 s left") or, when stderr is not a terminal (a batch log, CI),
// into plain log lines at each stage change and every 25 %.

#include <chrono>
#include <mutex>
#include <string>
#include <string_view>

#include "core/progress.h"

namespace u3mscan::cli {

class ProgressBar {
 public:
  // quiet: draw nothing. prefix: shown before the stage (e.g. the capture name in a batch).
  explicit ProgressBar(bool quiet, std::string prefix = "");
  ~ProgressBar();

  ProgressCallback Callback();
  void Update(std::string_view stage, double fraction);
  // Ends the current line on a terminal so later output starts clean.
  void Finish();

 private:
  using Clock = std::chrono::steady_clock;
  bool quiet_;
  bool terminal_;
  std::string prefix_;
  std::string stage_;
  Clock::time_point stage_start_;
  int last_quarter_ = -1;
  bool line_open_ = false;
  std::mutex mutex_;
};

}  // namespace u3mscan::cli
