// libFuzzer target: the .u3ma (restricted ZIP) reader on bytes in memory (u3m/u3ma_archive.h).
//
// Contract under test: ParseArchive either returns the entries or throws InputError; nothing else
// escapes, and it never allocates beyond its limits (the limits here are small so that a bomb the
// reader failed to stop shows up as an out-of-memory report, not as a slow run). Entries it
// accepts are never unsafe names (u3m/relative_path.h, kExact); names that only break the 1.1
// pattern are read with a warning and never written, so the rewrite round trip
// (SerializeArchive -> ParseArchive gives the entries back byte for byte) is checked only when every
// accepted name is writable.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <span>
#include <string>
#include <vector>

#include "core/error.h"
#include "u3m/relative_path.h"
#include "u3m/u3ma_archive.h"

namespace {

constexpr const char* kSourceName = "fuzz/material.u3ma";

u3mscan::ArchiveLimits FuzzLimits() {
  u3mscan::ArchiveLimits limits;
  limits.max_entries = 256;
  limits.max_entry_bytes = 16u << 20;  // 16 MiB
  limits.max_total_bytes = 64u << 20;  // 64 MiB, far below libFuzzer's 2 GiB RSS limit
  return limits;
}

[[noreturn]] void Fail(const char* what, const std::string& detail) {
  std::fprintf(stderr, "%s: %s\n", what, detail.c_str());
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const u3mscan::ArchiveLimits limits = FuzzLimits();
  std::vector<std::string> warnings;
  std::vector<u3mscan::ArchiveEntry> entries;
  try {
    entries = u3mscan::ParseArchive(std::span<const std::uint8_t>(data, size), kSourceName, limits, &warnings);
  } catch (const u3mscan::InputError&) {
    return 0;
  }
  std::uint64_t total = 0;
  bool all_writable = true;
  for (const u3mscan::ArchiveEntry& entry : entries) {
    const u3mscan::RelativePathCheck check = u3mscan::CheckRelativePath(entry.name, u3mscan::PathSpelling::kExact);
    if (check.unsafe) Fail("accepted an unsafe entry name", entry.name + ": " + check.unsafe_reason);
    if (!check.problems.empty()) all_writable = false;
    if (entry.data.size() > limits.max_entry_bytes) Fail("accepted an entry above the limit", entry.name);
    total += entry.data.size();
  }
  if (total > limits.max_total_bytes) Fail("accepted more bytes than the limit", std::to_string(total));
  if (!all_writable) return 0;  // read with a warning; the writer refuses such names by design

  u3mscan::ArchiveWriteOptions options;
  options.modified_utc = 1700000000;  // fixed, so a failure reproduces
  std::vector<std::uint8_t> bytes;
  try {
    bytes = u3mscan::SerializeArchive(entries, "fuzz/rewritten.u3ma", options);
  } catch (const u3mscan::InputError& e) {
    Fail("entries the reader accepted cannot be written", e.what());
  }
  std::vector<u3mscan::ArchiveEntry> again;
  try {
    again = u3mscan::ParseArchive(bytes, "fuzz/rewritten.u3ma", limits);
  } catch (const u3mscan::InputError& e) {
    Fail("our own archive does not read back", e.what());
  }
  if (again.size() != entries.size()) Fail("entry count changed in a rewrite", std::to_string(again.size()));
  for (std::size_t i = 0; i < entries.size(); ++i) {
    if (again[i].name != entries[i].name || again[i].data != entries[i].data) Fail("entry changed in a rewrite", entries[i].name);
  }
  return 0;
}
