#pragma once
// Loading and saving a material with its files: a `.u3m` beside its textures, or one `.u3ma`
// package (docs/u3m.md, "Files").
//
// Saving never leaves a half-written material: everything is checked and every file is written
// into a temporary folder beside the output first; textures are then renamed into place and the
// `.u3m` comes last (a `.u3ma` is one atomic rename). On any error nothing new stays behind.
// Loading a `.u3ma` unpacks it into a private temporary folder (removed when the LoadedMaterial
// goes away); nothing is ever written outside it.

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "u3m/material.h"
#include "u3m/material_json.h"

namespace u3mscan {

struct LoadedMaterial {
  Material material;
  SchemaVersion version = SchemaVersion::k1_1;  // the file's schema
  std::vector<Issue> issues;                    // deviations the reader tolerated
  std::filesystem::path source;                 // the .u3m or .u3ma as given
  std::string u3m_name;                         // the .u3m's file name (inside the package for .u3ma)
  std::filesystem::path base_dir;               // where the material's relative paths resolve
  std::shared_ptr<const std::filesystem::path> unpacked_dir;  // .u3ma: removed with the last copy

  std::filesystem::path Resolve(const std::string& relative_path) const { return base_dir / relative_path; }
};

// Reads a .u3m or .u3ma (by extension). Throws InputError when the file cannot be read as a U3M.
LoadedMaterial LoadMaterial(const std::filesystem::path& path);

enum class MissingFiles {
  kRefuse,  // a referenced file that does not exist is an error
  kDrop,    // drop the reference (texture -> null, preview -> null, FAB file -> "null"), with a note
};

struct SaveOptions {
  std::optional<SchemaVersion> version;  // unset: the lowest version that holds the content
  MissingFiles missing_files = MissingFiles::kRefuse;
  // Set every constant to the mean of its texture's final value (conventions: a reader without the
  // texture gets the right average). Needs the texture files to be readable images.
  bool update_constants = true;
  // Where a texture's pixel count disagrees with its size and dpi by more than 2 % (and 1 px),
  // keep the physical size and recompute dpi (textures) or keep dpi and recompute the size (previews).
  bool fix_image_geometry = true;
  bool update_modified = true;  // the specification: the last writer updates `modified`
  bool overwrite = false;       // replace an existing output (and files of the same name)
};

struct SaveResult {
  SchemaVersion version = SchemaVersion::k1_1;
  Material written;                  // the material as written (paths, constants, ids updated)
  std::vector<Issue> notes;          // what was changed on the way
  std::vector<std::string> files;    // relative paths of the files written besides the .u3m
};

// Writes `material`, whose relative paths resolve in `base_dir`, to `out` (.u3m or .u3ma). Files
// keep their relative paths when the conventions allow them, else get the nearest allowed name.
// Throws InputError (and writes nothing) on bad input, missing files (kRefuse), a version that
// cannot hold the content, or an existing output without `overwrite`.
SaveResult SaveMaterial(const Material& material, const std::filesystem::path& base_dir,
                        const std::filesystem::path& out, const SaveOptions& options = {});

// Pixel count `pixels` agrees with `size_mm` at `dpi`: within 2 % or 1 pixel (conventions, 1.1).
bool PixelSizeAgrees(int pixels, double size_mm, double dpi);

}  // namespace u3mscan
