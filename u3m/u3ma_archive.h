#pragma once
// The .u3ma package: a restricted ZIP (docs/u3m-conventions.md, ".u3ma package"). This module only
// moves bytes in and out of the archive; material_io puts a material and its textures into it.
// Details and limits: docs/u3ma-and-textures.md.
//
// Written archives are byte-exact to the conventions: store or deflate, UTF-8 flag, no extra fields,
// no comments, no zip64, no data descriptors, version-made-by 0x003F, version-needed 0x14, DOS times
// in UTC, external attributes 0, unique relative names, nothing before the first entry or after the
// end record. Entry names follow the project's one path rule (u3m/relative_path.h, exact spelling).
// Reading refuses anything that could escape or exhaust the output: absolute or `..`
// names, backslashes, duplicate names, symlinks, encryption, sizes or CRCs that do not add up, and
// archives that would unpack to more than ArchiveLimits allow. Harmless habits of other tools (extra
// fields, data descriptors, other made-by versions, folder entries, an archive comment, names that
// break only the 1.1 path pattern) are read and reported as warnings.

#include <cstdint>
#include <ctime>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "u3m/relative_path.h"  // entry names follow its rule; RelativePathProblem(name) says why one fails

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

enum class ArchiveCompression {
  kStore,
  kDeflate,  // per entry: stored instead when deflate would not shrink it (judged on the first
             // 256 KiB for larger entries) or would exceed the default
             // ArchiveLimits::max_compression_ratio (so our own reader always accepts it)
};

struct ArchiveWriteOptions {
  ArchiveCompression compression = ArchiveCompression::kDeflate;
  std::time_t modified_utc = 0;  // 0 = now; fixed for reproducible archives
};

// Reads every entry, in central-directory order; folder entries ("textures/") are skipped.
// Throws InputError naming the archive, the entry and what was expected. Deviations that are safe
// to read (extra fields, data descriptors, other version fields, comments) are appended to
// `warnings` when given, else logged as warnings.
std::vector<ArchiveEntry> ReadArchive(const std::filesystem::path& path, const ArchiveLimits& limits = {},
                                      std::vector<std::string>* warnings = nullptr);
// The same on bytes already in memory; `archive_name` is used in messages.
std::vector<ArchiveEntry> ParseArchive(std::span<const std::uint8_t> bytes, const std::string& archive_name,
                                       const ArchiveLimits& limits = {},
                                       std::vector<std::string>* warnings = nullptr);

// Writes atomically (temporary file, then rename). Throws InputError on bad names or I/O failure;
// names are checked before anything is written.
void WriteArchive(const std::filesystem::path& path, const std::vector<ArchiveEntry>& entries,
                  const ArchiveWriteOptions& options = {});
// The archive bytes WriteArchive writes; `archive_name` is used in messages.
std::vector<std::uint8_t> SerializeArchive(const std::vector<ArchiveEntry>& entries, const std::string& archive_name,
                                           const ArchiveWriteOptions& options = {});

// Reads the archive (all checks above) and writes its entries below `out_dir`, which must not exist
// or be an empty folder. Everything is unpacked into a temporary sibling folder first and renamed
// into place, so a failure leaves nothing behind and no file is ever written outside `out_dir`.
// Returns the entry names written.
std::vector<std::string> ExtractArchive(const std::filesystem::path& archive, const std::filesystem::path& out_dir,
                                        const ArchiveLimits& limits = {},
                                        std::vector<std::string>* warnings = nullptr);

}  // namespace u3mscan
