// `u3mscan convert IN OUT`: any U3M/U3MA to .u3m (+ textures) or .u3ma, up- or downgrading the schema.
#include <filesystem>
#include <iostream>
#include <memory>

#include "cli/command.h"
#include "core/error.h"
#include "core/logging.h"
#include "u3m/material_io.h"
#include "u3m/validate.h"

namespace u3mscan::cli {
namespace {

U3MSCAN_REGISTER_COMMAND(kConvertCommand, "convert", "Convert a U3M/U3MA to .u3m or .u3ma, schema 1.0 or 1.1", 30,
                         [](CLI::App& sub) {
  auto in = std::make_shared<std::string>();
  auto out = std::make_shared<std::string>();
  auto schema = std::make_shared<std::string>("auto");
  auto options = std::make_shared<SaveOptions>();
  auto drop_missing = std::make_shared<bool>(false);
  auto keep_constants = std::make_shared<bool>(false);
  auto keep_modified = std::make_shared<bool>(false);
  sub.add_option("IN", *in, "Input .u3m or .u3ma")->required();
  sub.add_option("OUT", *out, "Output .u3m (textures are written beside it) or .u3ma")->required();
  sub.add_option("--schema", *schema, "Schema version to write: auto (lowest that holds the content), 1.0 or 1.1")
      ->check(CLI::IsMember({"auto", "1.0", "1.1"}))
      ->capture_default_str();
  sub.add_flag("--drop-missing", *drop_missing, "Write the material without references to files that do not exist");
  sub.add_flag("--keep-constants", *keep_constants, "Keep the constants as they are instead of the texture means");
  sub.add_flag("--keep-modified", *keep_modified, "Keep the 'modified' time instead of setting it to now");
  sub.add_flag("-f,--force", options->overwrite, "Replace an existing output and files of the same name");
  sub.footer(
      "Converts between 1.0 and 1.1: image sizes cm <-> mm, dpi number <-> {x, y}, anisotropy rotation\n"
      "degrees <-> turns, 1.0 null parameters -> 1.1 defaults. Timestamps are written in UTC with 'Z'\n"
      "(zone-less input times are read as UTC), ids as lowercase v4 UUIDs. Textures, previews and the\n"
      "FAB physics file are carried along, and every foreign 'custom' section is kept unchanged.\n"
      "Constants are set to the mean of their textures and sizes/dpi fixed where they disagree with\n"
      "the pixel count. Refuses (exit 2) when the chosen version cannot hold the content, e.g. a side,\n"
      "physics or preview in 1.0. The output is validated after writing (exit 1 if it is not valid).");
  return std::function<int()>([=] {
    if (*schema == "1.0") options->version = SchemaVersion::k1_0;
    if (*schema == "1.1") options->version = SchemaVersion::k1_1;
    options->missing_files = *drop_missing ? MissingFiles::kDrop : MissingFiles::kRefuse;
    options->update_constants = !*keep_constants;
    options->update_modified = !*keep_modified;
    const LoadedMaterial loaded = LoadMaterial(*in);
    for (const Issue& issue : loaded.issues)
      LogWarning() << *in << ": " << (issue.pointer.empty() ? std::string("(file)") : issue.pointer) << ": " << issue.message;
    const SaveResult result = SaveMaterial(loaded.material, loaded.base_dir, *out, *options);
    for (const Issue& note : result.notes) LogInfo() << *out << ": " << note.pointer << ": " << note.message;
    const ValidationReport report = ValidateMaterialFile(*out, {true, !*keep_constants});
    const bool package = std::filesystem::path(*out).extension() == ".u3ma";
    std::cout << "wrote " << *out << " (U3M " << SchemaVersionName(result.version) << ", " << result.files.size()
              << (package ? " files in the package)\n" : " files beside the material)\n");
    if (!report.valid()) {
      std::cout << *out << ": INVALID after conversion (" << report.errors() << " errors)\n";
      for (const Issue& issue : report.issues)
        if (issue.severity == IssueSeverity::kError) std::cout << "  error   " << issue.pointer << ": " << issue.message << "\n";
      return kExitFailed;
    }
    return kExitOk;
  });
});

}  // namespace
}  // namespace u3mscan::cli
