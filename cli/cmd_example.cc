// `u3mscan example -o DIR`: writes a complete example U3M from built-in values and validates it.
#include <iostream>
#include <memory>

#include "cli/command.h"
#include "core/logging.h"
#include "u3m/example_material.h"
#include "u3m/validate.h"

namespace u3mscan::cli {
namespace {

U3MSCAN_REGISTER_COMMAND(kExampleCommand, "example", "Write a complete example U3M from built-in values and validate it",
                         10, [](CLI::App& sub) {
  auto out_dir = std::make_shared<std::string>();
  auto schema = std::make_shared<std::string>("auto");
  auto package = std::make_shared<bool>(false);
  auto file_name = std::make_shared<std::string>("example");
  auto options = std::make_shared<ExampleOptions>();
  sub.add_option("-o,--output", *out_dir, "Output folder (created if missing)")->required();
  sub.add_option("--schema", *schema, "auto (1.1, with preview and physics), 1.0 (no preview, no physics) or 1.1")
      ->check(CLI::IsMember({"auto", "1.0", "1.1"}))
      ->capture_default_str();
  sub.add_flag("--package", *package, "Write one .u3ma package instead of a .u3m with a textures/ folder");
  sub.add_option("--file-name", *file_name, "File name without extension")->capture_default_str();
  sub.add_option("--size", options->size_px, "Map size in pixels (multiple of 32)")->capture_default_str();
  sub.add_option("--pitch-mm", options->pitch_mm, "Physical pixel size in mm")->capture_default_str();
  sub.add_flag("-f,--force", options->overwrite, "Replace an existing example");
  sub.footer(
      "Writes a procedural plain-weave fabric: basecolor (8-bit sRGB PNG), normal (16-bit PNG, OpenGL),\n"
      "roughness (8-bit PNG) and displacement (16-bit PNG) maps, constants equal to the map means, and\n"
      "a 'u3mscan' custom section that states the displacement unit. Then validates the result.\n"
      "Exit status: 0 written and valid, 1 written but invalid, 2 could not write.");
  return std::function<int()>([=] {
    if (*schema == "1.0") options->version = SchemaVersion::k1_0;
    if (*schema == "1.1") options->version = SchemaVersion::k1_1;
    const std::filesystem::path out =
        std::filesystem::path(*out_dir) / (*file_name + (*package ? ".u3ma" : ".u3m"));
    const SaveResult result = WriteExampleMaterial(out, *options);
    for (const Issue& note : result.notes) LogDebug() << out.string() << ": " << note.pointer << ": " << note.message;
    const ValidationReport report = ValidateMaterialFile(out);
    std::cout << "wrote " << out.string() << " (U3M " << SchemaVersionName(result.version) << ", "
              << result.files.size() << " files: ";
    for (std::size_t i = 0; i < result.files.size(); ++i) std::cout << (i ? ", " : "") << result.files[i];
    std::cout << ")\n" << out.string() << ": " << (report.valid() ? "valid" : "INVALID") << " (" << report.errors()
              << " errors, " << report.warnings() << " warnings)\n";
    for (const Issue& issue : report.issues)
      std::cout << "  " << (issue.severity == IssueSeverity::kError ? "error  " : "warning") << " " << issue.pointer
                << ": " << issue.message << "\n";
    return report.valid() ? kExitOk : kExitFailed;
  });
});

}  // namespace
}  // namespace u3mscan::cli
