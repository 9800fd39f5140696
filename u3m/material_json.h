#pragma once
// U3M JSON text <-> Material, schema 1.0 and 1.1 (docs/u3m.md).
//
// Reading is tolerant where real files break rules and strict where a value cannot be trusted:
//  - tolerated, reported as an Issue with its JSON pointer: zone-less timestamps (read as UTC),
//    offsets, braces/uppercase in ids, missing or extra keys, keys of the other version, the other
//    version's dpi or normal form, null parameters in 1.1, out-of-range values, ior below 1,
//    backslashes or "." segments in paths, ...
//  - refused with InputError(file, pointer, expected): invalid JSON (truncated, NaN, comments),
//    duplicate keys, numbers beyond +-1e9 in the material, wrong types, unknown schema versions,
//    unparsable timestamps, and paths that could leave the material's folder (absolute, "..",
//    drive letters).
// `custom` and `metadata` are kept as JsonValue: same keys, order, values and number spelling.
//
// Writing produces text valid against the official schema of its version and the conventions:
// UTC "Z" timestamps, lowercase v4 UUID without braces, cm (1.0) or mm (1.1), dpi number (1.0) or
// {x, y} (1.1), anisotropy rotation in degrees (1.0) or turns (1.1), no null parameter in 1.1.
// It picks the lowest version that holds the content unless one is forced, and refuses with an
// InputError naming what a forced version cannot hold or a path it may not write.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "u3m/material.h"

namespace u3mscan {

enum class IssueSeverity {
  kError,    // breaks the official schema or a rule of the conventions (the reader coped)
  kWarning,  // legal but dubious, or something a writer changed
};

struct Issue {
  IssueSeverity severity = IssueSeverity::kWarning;
  std::string pointer;  // JSON pointer into the file, "/material/front/ior/constant"
  std::string message;
};

struct MaterialReadResult {
  Material material;
  SchemaVersion version = SchemaVersion::k1_1;  // the file's "schema"
  std::vector<Issue> issues;
};

// `file` names the source in issues and errors.
MaterialReadResult ReadMaterialJson(std::string_view text, const std::string& file);

struct MaterialWriteOptions {
  std::optional<SchemaVersion> version;  // unset: the lowest version that holds the content
  int indent = 4;
};

struct MaterialWriteResult {
  std::string text;
  SchemaVersion version = SchemaVersion::k1_1;
  std::vector<Issue> notes;  // what the writer had to change (new id, null parameter -> default, ...)
};

// `file` names the destination in errors.
MaterialWriteResult WriteMaterialJson(const Material& material, const MaterialWriteOptions& options,
                                      const std::string& file);

// "2021-10-19T15:41:23Z", with ".fff" only when the milliseconds are not zero.
std::string FormatUtcTimestamp(std::int64_t utc_ms);

struct ParsedTimestamp {
  std::int64_t utc_ms = 0;
  bool has_zone = false;     // "Z" or an offset was given
  bool has_offset = false;   // a numeric offset other than "Z"
  bool space_separator = false;
};
// RFC 3339 date-time, plus the zone-less and space-separated forms found in the wild.
std::optional<ParsedTimestamp> ParseTimestamp(std::string_view text);

}  // namespace u3mscan
