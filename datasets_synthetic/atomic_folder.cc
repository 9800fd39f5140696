#include "datasets_synthetic/atomic_folder.h"

#include <unistd.h>

#include <string>
#include <system_error>

#include "core/error.h"

namespace u3mscan::synthetic {
namespace fs = std::filesystem;

void WriteFolderAtomically(const fs::path& out_dir, const std::function<void(const fs::path& staging)>& write) {
  std::error_code ec;
  if (fs::exists(out_dir, ec) && !(fs::is_directory(out_dir, ec) && fs::is_empty(out_dir, ec))) {
    throw InputError(out_dir.string(), "", "an output folder that does not exist yet or is empty");
  }
  const fs::path target = fs::absolute(out_dir).lexically_normal();
  const fs::path parent = target.parent_path();
  fs::create_directories(parent, ec);
  if (ec) throw InputError(out_dir.string(), "", "a parent folder that can be created: " + ec.message());
  // Built with append() rather than operator+ on a literal: GCC 12 warns falsely (-Wrestrict) there.
  std::string temp_name = ".";
  temp_name.append(target.filename().string()).append(".partial-").append(std::to_string(::getpid()));
  const fs::path temp = parent / temp_name;
  fs::remove_all(temp, ec);
  try {
    fs::create_directories(temp);
    write(temp);
    if (fs::exists(target)) fs::remove(target);  // the empty folder the caller may have made
    fs::rename(temp, target);
  } catch (...) {
    std::error_code ignored;
    fs::remove_all(temp, ignored);
    throw;
  }
}

}  // namespace u3mscan::synthetic
