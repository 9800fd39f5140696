#pragma once
// The subcommand table of the `u3mscan` executable. Each subcommand lives in its own
// cli/cmd_<name>.cc and registers itself with a static U3MSCAN_REGISTER_COMMAND; main() builds the
// CLI11 app from the table. A subcommand parses straight into its library's Options struct and
// calls the library: the CLI holds no logic of its own.

#include <CLI/CLI.hpp>
#include <functional>
#include <string>
#include <vector>

namespace u3mscan::cli {

// Exit codes shared by all subcommands.
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailed = 1;    // ran, but the result is negative (invalid file, a capture failed)
inline constexpr int kExitUsage = 2;     // bad arguments or unreadable input

struct Command {
  std::string name;
  std::string summary;
  int order = 100;  // position in `u3mscan --help` (main job first)
  // Adds options to `sub` and returns the action to run when `sub` was chosen (returns exit code).
  std::function<std::function<int()>(CLI::App& sub)> setup;
};

std::vector<Command>& CommandTable();

struct CommandRegistrar {
  explicit CommandRegistrar(Command command) { CommandTable().push_back(std::move(command)); }
};

#define U3MSCAN_REGISTER_COMMAND(var, ...) \
  static const ::u3mscan::cli::CommandRegistrar var { ::u3mscan::cli::Command{__VA_ARGS__} }

}  // namespace u3mscan::cli
