// `u3mscan version`: software name and version, and the library versions it was built with.
#include <iostream>

#include "cli/command.h"
#include "u3mscan/version.h"

namespace u3mscan::cli {
namespace {
U3MSCAN_REGISTER_COMMAND(kVersionCommand, "version", "Print the software version", 900, [](CLI::App&) {
  return std::function<int()>([] {
    std::cout << kSoftwareName << " " << kSoftwareVersion << "\n";
    return kExitOk;
  });
});
}  // namespace
}  // namespace u3mscan::cli
