#pragma once
// Batch: many capture folders through one processing function, each to its own output folder.
// One capture that fails is reported and the others still finish; a summary table and an exit code
// (0 all done, 1 some failed) close the run. Runs are reproducible, so a batch can be resumed with
// `skip_existing` and split over machines by any job scheduler (docs/batch.md).

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace u3mscan {

struct CaptureJob {
  std::filesystem::path capture_dir;
  std::filesystem::path out_dir;  // where this capture's material and report go
  std::string name;               // file-system safe name of the material (from the folder name)
};

// Expands the command line's inputs into jobs. Each input is a capture folder (holds capture.json)
// or a folder of capture folders (every direct sub-folder with a capture.json, sorted by name).
// With exactly one capture, its output goes straight into `out_dir`; with several, into
// `out_dir/<name>/`. Throws InputError for an input that is neither, or for two captures that
// would write to the same output folder.
std::vector<CaptureJob> PlanBatch(const std::vector<std::filesystem::path>& inputs, const std::filesystem::path& out_dir);

// A name made of [A-Za-z0-9._-] only (other characters become '_'), never empty, never "." or "..".
std::string SafeMaterialName(const std::string& name);

struct JobOutcome {
  CaptureJob job;
  bool ok = false;
  bool skipped = false;  // output was already complete (skip_existing)
  std::string error;
  double seconds = 0.0;
};

struct BatchOptions {
  int parallel_captures = 1;   // captures processed at the same time
  bool skip_existing = false;  // skip captures whose output is complete (IsOutputComplete)
};

// Processes one capture; throws (InputError or other) on failure. Must write nothing partial.
using CaptureProcessor = std::function<void(const CaptureJob&)>;
// Whether a job's output is already complete.
using CompletionCheck = std::function<bool(const CaptureJob&)>;

std::vector<JobOutcome> RunBatch(const std::vector<CaptureJob>& jobs, const CaptureProcessor& process,
                                 const CompletionCheck& is_complete, const BatchOptions& options);

// Plain-text table: capture, status, seconds, error.
std::string FormatBatchSummary(const std::vector<JobOutcome>& outcomes);
// 0 when every job succeeded or was skipped, 1 when any failed.
int BatchExitCode(const std::vector<JobOutcome>& outcomes);

}  // namespace u3mscan
