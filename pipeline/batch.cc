#include "pipeline/batch.h"

#include <algorithm>
#include <atomic>
#include <iomanip>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>

#include "core/elapsed.h"
#include "core/error.h"
#include "core/logging.h"

namespace u3mscan {
namespace fs = std::filesystem;

namespace {
bool IsCaptureFolder(const fs::path& dir) {
  std::error_code ec;
  return fs::is_regular_file(dir / "capture.json", ec);
}
}  // namespace

std::string SafeMaterialName(const std::string& name) {
  std::string safe;
  for (char c : name) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '-' ||
                    c == '_' || c == '.';
    safe += ok ? c : '_';
  }
  // No leading or trailing dots: "." and ".." are never names, and hidden or trailing-dot files
  // break other tools (u3m-conventions: no trailing dot or space).
  while (!safe.empty() && safe.front() == '.') safe.erase(safe.begin());
  while (!safe.empty() && safe.back() == '.') safe.pop_back();
  return safe.empty() ? "material" : safe;
}

std::vector<CaptureJob> PlanBatch(const std::vector<fs::path>& inputs, const fs::path& out_dir) {
  std::vector<fs::path> captures;
  for (const fs::path& input : inputs) {
    std::error_code ec;
    if (!fs::is_directory(input, ec)) {
      throw InputError(input.string(), "", "a capture folder (with capture.json) or a folder of capture folders");
    }
    if (IsCaptureFolder(input)) {
      captures.push_back(input);
      continue;
    }
    std::vector<fs::path> children;
    for (const auto& entry : fs::directory_iterator(input)) {
      if (entry.is_directory() && IsCaptureFolder(entry.path())) children.push_back(entry.path());
    }
    if (children.empty()) {
      throw InputError(input.string(), "capture.json",
                       "a capture folder (with capture.json) or a folder holding capture folders; found neither");
    }
    std::sort(children.begin(), children.end());
    captures.insert(captures.end(), children.begin(), children.end());
  }

  std::vector<CaptureJob> jobs;
  std::map<std::string, fs::path> seen;
  for (const fs::path& capture : captures) {
    CaptureJob job;
    job.capture_dir = capture;
    const fs::path normalised = capture.lexically_normal();
    std::string base = (normalised.has_filename() ? normalised.filename() : normalised.parent_path().filename()).string();
    job.name = SafeMaterialName(base);
    job.out_dir = captures.size() == 1 ? out_dir : out_dir / job.name;
    if (auto [it, inserted] = seen.emplace(job.name, capture); !inserted) {
      throw InputError(capture.string(), "", "a capture folder name unique in the batch; '" + it->second.string() +
                                                 "' also writes to " + job.out_dir.string());
    }
    jobs.push_back(job);
  }
  return jobs;
}

std::vector<JobOutcome> RunBatch(const std::vector<CaptureJob>& jobs, const CaptureProcessor& process,
                                 const CompletionCheck& is_complete, const BatchOptions& options) {
  std::vector<JobOutcome> outcomes(jobs.size());
  std::atomic<std::size_t> next{0};
  auto worker = [&] {
    for (;;) {
      const std::size_t i = next.fetch_add(1);
      if (i >= jobs.size()) return;
      JobOutcome& outcome = outcomes[i];
      outcome.job = jobs[i];
      if (options.skip_existing && is_complete && is_complete(jobs[i])) {
        outcome.ok = true;
        outcome.skipped = true;
        LogInfo() << jobs[i].name << ": output complete, skipped";
        continue;
      }
      const double start = SteadySeconds();
      try {
        process(jobs[i]);
        outcome.ok = true;
      } catch (const std::exception& e) {
        outcome.ok = false;
        outcome.error = e.what();
        LogError() << jobs[i].name << ": " << e.what();
      }
      outcome.seconds = SteadySeconds() - start;
    }
  };
  const int workers = std::clamp(options.parallel_captures, 1, static_cast<int>(std::max<std::size_t>(1, jobs.size())));
  std::vector<std::thread> threads;
  for (int i = 1; i < workers; ++i) threads.emplace_back(worker);
  worker();
  for (auto& t : threads) t.join();
  return outcomes;
}

std::string FormatBatchSummary(const std::vector<JobOutcome>& outcomes) {
  std::size_t name_width = 7;
  for (const auto& o : outcomes) name_width = std::max(name_width, o.job.name.size());
  std::ostringstream table;
  table << std::left << std::setw(static_cast<int>(name_width)) << "capture" << "  " << std::setw(7) << "status"
        << "  " << std::right << std::setw(9) << "seconds" << "  error\n";
  int failed = 0, skipped = 0;
  for (const auto& o : outcomes) {
    const char* status = o.skipped ? "skipped" : o.ok ? "ok" : "FAILED";
    failed += !o.ok;
    skipped += o.skipped;
    table << std::left << std::setw(static_cast<int>(name_width)) << o.job.name << "  " << std::setw(7) << status << "  "
          << std::right << std::setw(9) << std::fixed << std::setprecision(1) << o.seconds << "  " << o.error << "\n";
  }
  table << outcomes.size() << " captures: " << outcomes.size() - failed - skipped << " processed, " << skipped
        << " skipped, " << failed << " failed\n";
  return table.str();
}

int BatchExitCode(const std::vector<JobOutcome>& outcomes) {
  for (const auto& o : outcomes) {
    if (!o.ok) return 1;
  }
  return 0;
}

}  // namespace u3mscan
