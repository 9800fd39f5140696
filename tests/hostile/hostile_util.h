#pragma once
// Helpers of the hostile-input tests: run the built `u3mscan` in a child process with bounded
// memory and time, a temporary folder per test, and a minimal ZIP writer for the archives that are
// too large to check in (independent of u3m/u3ma_archive.cc, whose reader is under test).

#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace u3mscan::hostile {

namespace fs = std::filesystem;

struct RunResult {
  int exit_code = -1;    // valid when !signalled
  int signal = 0;        // the signal that ended the process, 0 when it exited
  std::string output;    // stdout and stderr, interleaved as written
};

// Runs `u3mscan args...` with TMPDIR=`tmp_dir`, at most kMemoryLimitBytes of address space (so an
// allocation that a header tricked the program into fails instead of swapping the machine) and
// kCpuLimitSeconds of CPU. Set U3MSCAN_HOSTILE_NO_RLIMIT=1 for a sanitizer build of u3mscan.
RunResult RunU3mscan(const std::vector<std::string>& args, const fs::path& tmp_dir);

// Several runs at once (each as RunU3mscan, with its own TMPDIR): the cost of a run is mostly the
// start of a process that loads a few hundred shared libraries, so they overlap on the cores.
struct RunSpec {
  std::vector<std::string> args;
  fs::path tmp_dir;
};
std::vector<RunResult> RunU3mscanAll(const std::vector<RunSpec>& runs);

inline constexpr std::uint64_t kMemoryLimitBytes = std::uint64_t{6} << 30;
inline constexpr int kCpuLimitSeconds = 60;

// The process ended by itself, with `exit_code`, and printed no sign of a crash, an abort, a
// sanitizer report or an uncaught exception; every string of `mentions` is in its output.
::testing::AssertionResult CleanExit(const RunResult& run, int exit_code, const std::vector<std::string>& mentions);

// `dir` does not exist or holds nothing (no file, no hidden temporary, no empty sub-folder).
::testing::AssertionResult NothingIn(const fs::path& dir);

// A folder unique to the running test, removed at the end.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

// Where the checked-in corpus lives (tests/hostile).
fs::path CorpusDir();

std::string ReadFile(const fs::path& path);
void WriteFile(const fs::path& path, const std::string& bytes);

// A ZIP archive from (name, data, deflate?) entries; sizes and CRCs are honest.
struct ZipEntrySpec {
  std::string name;
  std::string data;
  bool deflate = false;
};
std::string BuildZip(const std::vector<ZipEntrySpec>& entries);

}  // namespace u3mscan::hostile
