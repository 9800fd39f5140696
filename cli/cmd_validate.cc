// `u3mscan validate FILE...`: every error and warning of each U3M/U3MA file, with its JSON pointer.
#include <iostream>
#include <memory>

#include "cli/command.h"
#include "core/error.h"
#include "u3m/validate.h"

namespace u3mscan::cli {
namespace {

void PrintIssues(const std::vector<Issue>& issues) {
  for (const Issue& issue : issues)
    std::cout << "  " << (issue.severity == IssueSeverity::kError ? "error  " : "warning") << " "
              << (issue.pointer.empty() ? std::string("(file)") : issue.pointer) << ": " << issue.message << "\n";
}

U3MSCAN_REGISTER_COMMAND(kValidateCommand, "validate", "Check U3M/U3MA files against the schema and the conventions", 20,
                         [](CLI::App& sub) {
  auto files = std::make_shared<std::vector<std::string>>();
  auto options = std::make_shared<ValidationOptions>();
  auto skip_files = std::make_shared<bool>(false);
  auto skip_constants = std::make_shared<bool>(false);
  sub.add_option("FILE", *files, "U3M (.u3m, textures beside it) or U3MA (.u3ma) files")->required();
  sub.add_flag("--no-files", *skip_files, "Check the JSON only: skip texture files, pixel sizes and constants");
  sub.add_flag("--no-constants", *skip_constants, "Skip the constant-versus-texture-mean check (reads no pixels)");
  sub.footer(
      "Checks the official JSON schema of the file's version (1.0 or 1.1), the conventions (UTC 'Z'\n"
      "timestamps, lowercase v4 UUID, relative '/' paths, ...), that every texture, preview and FAB\n"
      "file exists and is readable, that pixel counts agree with size and dpi (2 % or 1 px), and that\n"
      "each constant is the mean of its texture's final value.\n"
      "Exit status: 0 all valid (warnings allowed), 1 some file invalid, 2 some file unreadable.");
  return std::function<int()>([files, options, skip_files, skip_constants] {
    options->check_files = !*skip_files;
    options->check_constants = !*skip_constants;
    int exit_code = kExitOk;
    for (const std::string& file : *files) {
      try {
        const ValidationReport report = ValidateMaterialFile(file, *options);
        std::cout << file << ": " << (report.valid() ? "valid" : "INVALID") << " (U3M "
                  << SchemaVersionName(report.version) << ", " << report.errors() << " errors, " << report.warnings()
                  << " warnings)\n";
        PrintIssues(report.issues);
        if (!report.valid() && exit_code == kExitOk) exit_code = kExitFailed;
      } catch (const InputError& e) {
        std::cout << file << ": UNREADABLE\n  error   " << (e.field().empty() ? std::string("(file)") : e.field())
                  << ": " << e.expected() << "\n";
        exit_code = kExitUsage;
      }
    }
    return exit_code;
  });
});

}  // namespace
}  // namespace u3mscan::cli
