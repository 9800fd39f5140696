#pragma once
// Small helpers shared by the u3m_package tests: the shared temporary folder and shell calls.

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <string>

#include "tests/support/temp_dir.h"

namespace u3mscan {

#ifdef U3MSCAN_SYSTEM_PYTHON
inline const char* const kSystemPython = U3MSCAN_SYSTEM_PYTHON;
#else
inline const char* const kSystemPython = "/usr/bin/python3";
#endif

using test::TempDir;  // tests/support/temp_dir.h

// Single-quoted for /bin/sh.
inline std::string Quote(const std::filesystem::path& path) {
  std::string out = "'";
  for (char c : path.string()) {
    if (c == '\'') out += "'\\''"; else out.push_back(c);
  }
  return out + "'";
}

// Exit status of a shell command (-1 when it could not run).
inline int RunCommand(const std::string& command) {
  const int status = std::system(command.c_str());
  if (status == -1 || !WIFEXITED(status)) return -1;
  return WEXITSTATUS(status);
}

}  // namespace u3mscan
