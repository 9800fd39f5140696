#include "cli/size_option.h"

#include <cstdio>

#include "core/error.h"

namespace u3mscan::cli {

void ParseSizeOption(const std::string& text, const std::string& example, int* width, int* height) {
  int w = 0, h = 0;
  char x = 0, extra = 0;
  if (std::sscanf(text.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X')) {
    throw InputError("--size", "", "WIDTHxHEIGHT in pixels, e.g. " + example + ", got '" + text + "'");
  }
  *width = w;
  *height = h;
}

}  // namespace u3mscan::cli
