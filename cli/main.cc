// u3mscan: multi-light photographs of a fabric -> a complete U3M material.
// main() only builds the subcommand table (cli/cmd_*.cc) and maps errors to exit codes.

#include <algorithm>
#include <iostream>
#include <memory>

#include "cli/command.h"
#include "core/error.h"
#include "core/large_allocations.h"
#include "core/logging.h"
#include "u3mscan/version.h"

namespace u3mscan::cli {
std::vector<Command>& CommandTable() {
  static std::vector<Command> table;
  return table;
}
}  // namespace u3mscan::cli

int main(int argc, char** argv) {
  using namespace u3mscan;
  using namespace u3mscan::cli;
  KeepLargeAllocationsInTheHeap();  // before any image is allocated (core/large_allocations.h)

  CLI::App app{
      "u3mscan: turns multi-light photographs of a fabric (a capture folder) into a complete U3M "
      "material, and reads, checks and converts U3M files.",
      "u3mscan"};
  app.set_version_flag("--version", std::string(kSoftwareName) + " " + kSoftwareVersion);
  app.require_subcommand(1);
  bool quiet = false, verbose = false;
  app.add_flag("-q,--quiet", quiet, "Print only errors");
  app.add_flag("-v,--verbose", verbose, "Print debug messages");
  app.footer("Run 'u3mscan COMMAND --help' for the options of one command.");

  auto& table = CommandTable();
  std::stable_sort(table.begin(), table.end(), [](const Command& a, const Command& b) { return a.order < b.order; });
  std::function<int()> action;
  for (const Command& command : table) {
    CLI::App* sub = app.add_subcommand(command.name, command.summary);
    auto run = command.setup(*sub);
    sub->callback([&action, run] { action = run; });
  }

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? kExitOk : kExitUsage;
  }
  if (quiet) SetLogLevel(LogLevel::kError);
  if (verbose) SetLogLevel(LogLevel::kDebug);
  try {
    return action ? action() : kExitUsage;
  } catch (const InputError& e) {
    LogError() << e.what();
    return kExitUsage;
  } catch (const std::exception& e) {
    LogError() << "internal error: " << e.what();
    return kExitFailed;
  }
}
