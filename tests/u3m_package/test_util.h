#pragma once
// Small helpers shared by the u3m_package tests: a self-deleting temporary folder and shell calls.

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <stdexcept>
#include <string>

namespace u3mscan {

#ifdef U3MSCAN_SYSTEM_PYTHON
inline const char* const kSystemPython = U3MSCAN_SYSTEM_PYTHON;
#else
inline const char* const kSystemPython = "/usr/bin/python3";
#endif

// A fresh folder under the system temp dir, removed with everything in it at scope exit.
class TempDir {
 public:
  TempDir() {
    std::string pattern = (std::filesystem::temp_directory_path() / "u3m_package_test_XXXXXX").string();
    if (!mkdtemp(pattern.data())) throw std::runtime_error("mkdtemp failed");
    path_ = pattern;
  }
  ~TempDir() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

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
