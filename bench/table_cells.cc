#include "bench/table_cells.h"

#include <cmath>
#include <iomanip>
#include <sstream>

namespace u3mscan::bench {

std::string Fixed(double v, int digits) {
  if (!std::isfinite(v)) return "";
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << v;
  return s.str();
}

std::string Csv(const std::string& text) {
  if (text.find_first_of(",\"\n") == std::string::npos) return text;
  std::string out = "\"";
  for (char c : text) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

}  // namespace u3mscan::bench
