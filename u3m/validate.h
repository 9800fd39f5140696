#pragma once
// Validation of a U3M file (docs/u3m.md, "Validation"): every error and warning with its JSON
// pointer. Errors break the official schema of the file's version or a rule of the conventions;
// warnings are legal but dubious. Checks:
//  - schema: keys, types, enumerations, ranges, date-time, UUID, path pattern (the reader's issues);
//  - conventions: UTC timestamps, id form, path rules, plausible values (ior >= 1, the 1-for-0 bug);
//  - files: every texture, preview and FAB file exists and every image is readable;
//  - geometry: pixel count agrees with size and dpi within 2 % or 1 px (PixelSizeAgrees);
//  - constants: each constant is close to its texture's mean final value (ConstantAgrees).

#include <filesystem>
#include <string>
#include <vector>

#include "u3m/material_io.h"
#include "u3m/material_json.h"

namespace u3mscan {

struct ValidationOptions {
  bool check_files = true;      // existence, readability and pixel size of referenced files
  bool check_constants = true;  // constant vs texture mean (reads every texture)
};

struct ValidationReport {
  std::string file;
  SchemaVersion version = SchemaVersion::k1_1;
  std::vector<Issue> issues;
  int errors() const;
  int warnings() const;
  bool valid() const { return errors() == 0; }
};

// Throws InputError when the file cannot be read as a U3M at all (not JSON, wrong types, ...).
ValidationReport ValidateMaterialFile(const std::filesystem::path& path, const ValidationOptions& options = {});
ValidationReport ValidateLoadedMaterial(const LoadedMaterial& loaded, const ValidationOptions& options = {});

}  // namespace u3mscan
