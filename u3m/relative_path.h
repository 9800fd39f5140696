#pragma once
// Texture and file paths inside a U3M: relative to the .u3m, '/' separators (docs/u3m-conventions.md).
//
// Reading distinguishes three kinds of trouble: paths that could reach outside the material
// (absolute, drive letters, "..", control characters) are refused; harmless spelling slips
// (backslashes, "." or empty segments) are repaired; names that only break the 1.1 schema's
// `relative_file_path` pattern (trailing dot or space, reserved device names, <>:"|$% ...) are
// kept, and a writer renames them with SanitizeRelativePath.

#include <string>
#include <string_view>
#include <vector>

namespace u3mscan {

struct RelativePathCheck {
  std::string normalized;             // '/' separators, no "." or empty segments
  bool unsafe = false;                // must be refused: could escape the material's folder
  std::string unsafe_reason;          // why, when unsafe
  std::vector<std::string> repairs;   // what was repaired to get `normalized`
  std::vector<std::string> problems;  // what still breaks the conventions or the 1.1 pattern
};

RelativePathCheck CheckRelativePath(std::string_view path);

// True when `path` follows every rule of the conventions and the 1.1 schema's pattern, so a writer
// may write it unchanged. `why` (optional) receives the first rule broken.
bool IsWritableRelativePath(std::string_view path, std::string* why = nullptr);

// A writable path as close to `path` as possible: unsafe segments dropped, forbidden characters
// replaced by '_', trailing dots and spaces removed, reserved names prefixed with '_'.
std::string SanitizeRelativePath(std::string_view path);

}  // namespace u3mscan
