#pragma once
// The one rule for relative paths in this project: texture, preview and FAB paths inside a U3M and
// entry names inside a .u3ma (docs/u3m-conventions.md: relative, '/' separators, no "." or ".."
// segments, no leading '/', no drive letters, no backslashes, no trailing dot or space).
//
// Three kinds of trouble:
//  - unsafe: could reach outside the folder or confuse a file system (empty, longer than 1024
//    bytes, not UTF-8, control characters, absolute, drive letter, ':', ".."): always refused;
//  - spelling slips (backslashes, "." or empty segments): a U3M reader repairs them
//    (PathSpelling::kRepair, each noted in `repairs`); an archive entry name must already be in its
//    final spelling (PathSpelling::kExact), so there they are unsafe;
//  - problems: names that only break the 1.1 schema's `relative_file_path` pattern (trailing dot
//    or space, reserved device names, <>:"|$% ...): read with a warning, never written;
//    a writer renames them with SanitizeRelativePath.

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace u3mscan {

// Bytes; far beyond any real texture path, and below the 65535 a ZIP name field can hold.
constexpr std::size_t kMaxRelativePathBytes = 1024;

enum class PathSpelling {
  kRepair,  // U3M paths: backslashes read as '/', "." and empty segments dropped
  kExact,   // archive entry names: any slip is refused (the name is what lands on disk)
};

struct RelativePathCheck {
  std::string normalized;             // '/' separators, no "." or empty segments
  bool unsafe = false;                // must be refused
  std::string unsafe_reason;          // what was expected, when unsafe ("a relative path, not an absolute one")
  std::vector<std::string> repairs;   // what was repaired to get `normalized` (kRepair only)
  std::vector<std::string> problems;  // what still breaks the conventions or the 1.1 pattern
};

RelativePathCheck CheckRelativePath(std::string_view path, PathSpelling spelling = PathSpelling::kRepair);

// True when `path` follows every rule of the conventions and the 1.1 schema's pattern, so a writer
// may write it unchanged (CheckRelativePath with kExact, neither unsafe nor with problems). `why`
// (optional) receives the first rule broken.
bool IsWritableRelativePath(std::string_view path, std::string* why = nullptr);

// Why an archive entry name is not a writable relative path (the unsafe reason, else the first
// problem), or "" when it is one.
std::string RelativePathProblem(std::string_view name);

// A writable path as close to `path` as possible: unsafe segments dropped, forbidden characters
// (and the non-ASCII bytes of a segment that is not UTF-8) replaced by '_', trailing dots and
// spaces removed, reserved names prefixed with '_'.
std::string SanitizeRelativePath(std::string_view path);

// Well-formed UTF-8: no overlong forms, surrogates or code points past U+10FFFF.
bool IsValidUtf8(std::string_view text);

}  // namespace u3mscan
