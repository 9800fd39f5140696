#include "core/text_file.h"

#include <fstream>
#include <system_error>

#include "core/error.h"

namespace u3mscan {

void WriteTextFileAtomically(const std::filesystem::path& path, const std::string& text, const std::string& what) {
  const std::filesystem::path temp = path.string() + ".partial";
  {
    std::ofstream out(temp, std::ios::binary | std::ios::trunc);
    out << text;
    out.flush();
    if (!out) {
      std::error_code ignored;
      std::filesystem::remove(temp, ignored);
      throw InputError(path.string(), "", what);
    }
  }
  std::error_code ec;
  std::filesystem::rename(temp, path, ec);
  if (ec) {
    std::error_code ignored;
    std::filesystem::remove(temp, ignored);
    throw InputError(path.string(), "", what + " (rename: " + ec.message() + ")");
  }
}

}  // namespace u3mscan
