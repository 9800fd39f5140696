#pragma once
// The .u3ma package: a restricted ZIP (docs/u3m-conventions.md, ".u3ma package"). This module only
// moves bytes in and out of the archive; material_io puts a material and its textures into it.
//
// Written archives are byte-exact to the conventions: store or deflate, UTF-8 flag, no extra fields,
// no comments, no zip64, no data descriptors, version-made-by 0x003F, version-needed 0x14, DOS times
// in UTC, external attributes 0, unique relative names, nothing before the first entry or after the
// end record. Reading refuses anything that could escape or exhaust the output: absolute or `..`
// names, backslashes, duplicate names, symlinks, encryption, sizes or CRCs that do not add up, and
// archives that would unpack to more than ArchiveLimits allow.

#include <cstdint>
#include <ctime>
#include <filesystem>
#include <string>
#include <vector>

namespace u3mscan {

struct ArchiveEntry {
  std::string name;                 // relative, '/' separators, e.g. "textures/basecolor.png"
  std::vector<std::uint8_t> data;   // uncompressed bytes
};

struct ArchiveLimits {
  std::uint64_t max_entries = 4096;
  std::uint64_t max_entry_bytes = std::uint64_t{2} << 30;   // 2 GiB uncompressed per entry
  std::uint64_t max_total_bytes = std::uint64_t{8} << 30;   // 8 GiB uncompressed in all
  double max_compression_ratio = 1000.0;                    // zip-bomb guard per entry
};

enum class ArchiveCompression { kStore, kDeflate };

struct ArchiveWriteOptions {
  ArchiveCompression compression = ArchiveCompression::kDeflate;
  std::time_t modified_utc = 0;  // 0 = now; fixed for reproducible archives
};

// Reads every entry; throws InputError naming the archive, the entry and what was expected.
std::vector<ArchiveEntry> ReadArchive(const std::filesystem::path& path, const ArchiveLimits& limits = {});
// Writes atomically (temporary file, then rename). Throws InputError on bad names or I/O failure.
void WriteArchive(const std::filesystem::path& path, const std::vector<ArchiveEntry>& entries,
                  const ArchiveWriteOptions& options = {});

}  // namespace u3mscan
