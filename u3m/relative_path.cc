#include "u3m/relative_path.h"

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <regex>

namespace u3mscan {
namespace {

// The 1.1 schema's `relative_file_path` pattern, verbatim (ECMAScript, as JSON Schema uses).
const std::regex& SchemaPathPattern() {
  static const std::regex pattern(
      R"(^((?!(\.\.|\.|~|(([cC][oO][nN]|[pP][rR][nN]|[aA][uU][xX]|[cC][lL][oO][cC][kK]\$|[nN][uU][lL]|[cC][oO][mM][1-9]|[lL][pP][tT][1-9])(\.[^\/]*)?))\/)([^\x00-\x1F<>:"\/\\|\$%]{0,254}[^\x00-\x1F<>:"\/\\|\$%\.\x20|]\/))*(?!(\.\.|\.|~|(([cC][oO][nN]|[pP][rR][nN]|[aA][uU][xX]|[cC][lL][oO][cC][kK]\$|[nN][uU][lL]|[cC][oO][mM][1-9]|[lL][pP][tT][1-9])(\..*)?))$)([^\x00-\x1F<>:"\/\\|]{0,254}[^\x00-\x1F<>:"\/\\\.\x20|]$)$)",
      std::regex::ECMAScript | std::regex::optimize);
  return pattern;
}

std::vector<std::string> Split(std::string_view path, bool backslash_too) {
  std::vector<std::string> segments(1);
  for (char c : path) {
    if (c == '/' || (backslash_too && c == '\\')) segments.emplace_back();
    else segments.back() += c;
  }
  return segments;
}

bool IsReservedName(std::string_view segment) {
  std::string base(segment.substr(0, segment.find('.')));
  std::transform(base.begin(), base.end(), base.begin(), [](unsigned char c) { return std::tolower(c); });
  if (base == "con" || base == "prn" || base == "aux" || base == "nul" || base == "clock$") return true;
  if (base.size() == 4 && (base.rfind("com", 0) == 0 || base.rfind("lpt", 0) == 0) && base[3] >= '1' && base[3] <= '9')
    return true;
  return false;
}

bool HasDriveLetter(std::string_view path) {
  return path.size() >= 2 && std::isalpha(static_cast<unsigned char>(path[0])) && path[1] == ':';
}

// The first rule of the conventions or the 1.1 pattern that a safe, normalized path breaks, or "".
std::string SchemaProblem(const std::string& normalized) {
  for (const std::string& segment : Split(normalized, false)) {
    if (segment.back() == '.' || segment.back() == ' ') return "a segment ending in '.' or ' ' (Windows drops them)";
    if (IsReservedName(segment)) return "a reserved device name (CON, NUL, COM1, ...)";
  }
  if (!std::regex_match(normalized.begin(), normalized.end(), SchemaPathPattern()))
    return "characters the 1.1 relative_file_path pattern forbids (<>:\"|\\, and $% in folder names)";
  return "";
}

}  // namespace

RelativePathCheck CheckRelativePath(std::string_view path, PathSpelling spelling) {
  const bool repair = spelling == PathSpelling::kRepair;
  RelativePathCheck check;
  const auto refuse = [&](std::string reason) {
    check.unsafe = true;
    check.unsafe_reason = std::move(reason);
    return check;
  };
  if (path.empty()) return refuse("a non-empty path");
  if (path.size() > kMaxRelativePathBytes) return refuse("a path of at most " + std::to_string(kMaxRelativePathBytes) + " bytes");
  if (!IsValidUtf8(path)) return refuse("a path in valid UTF-8");
  for (unsigned char c : path)
    if (c < 0x20 || c == 0x7F) return refuse("a path without control characters");
  if (path.find('\\') != std::string_view::npos) {
    if (!repair) return refuse("'/' as the only separator, no backslash");
    check.repairs.push_back("backslashes replaced by '/'");
  }
  if (path.front() == '/' || path.front() == '\\') return refuse("a relative path, not an absolute one");
  if (HasDriveLetter(path)) return refuse("a path without a drive letter");
  std::vector<std::string> kept;
  bool dropped = false;
  for (std::string& segment : Split(path, repair)) {
    if (segment == "..") return refuse("a path without '..' segments (they could leave the folder)");
    if (segment.empty() || segment == ".") {
      if (!repair) return refuse("a path without empty or '.' segments ('//', './' or a trailing '/')");
      dropped = true;
      continue;
    }
    if (segment.find(':') != std::string::npos) return refuse("a path without ':' (drive letter or stream name)");
    kept.push_back(std::move(segment));
  }
  if (kept.empty()) return refuse("a path that names a file");
  if (dropped) check.repairs.push_back("'.' and empty segments removed");
  for (std::size_t i = 0; i < kept.size(); ++i) check.normalized += (i ? "/" : "") + kept[i];
  if (std::string problem = SchemaProblem(check.normalized); !problem.empty()) check.problems.push_back(problem);
  return check;
}

std::string RelativePathProblem(std::string_view name) {
  const RelativePathCheck check = CheckRelativePath(name, PathSpelling::kExact);
  if (check.unsafe) return check.unsafe_reason;
  return check.problems.empty() ? "" : check.problems.front();
}

bool IsWritableRelativePath(std::string_view path, std::string* why) {
  const std::string problem = RelativePathProblem(path);
  if (why) *why = problem;
  return problem.empty();
}

std::string SanitizeRelativePath(std::string_view path) {
  std::string out;
  for (std::string segment : Split(path, true)) {
    if (segment.empty() || segment == "." || segment == "..") continue;
    if (!IsValidUtf8(segment))  // e.g. a Latin-1 file name: keep its ASCII, mark the rest
      for (char& c : segment)
        if (static_cast<unsigned char>(c) >= 0x80) c = '_';
    for (char& c : segment) {
      const unsigned char u = static_cast<unsigned char>(c);
      if (u < 0x20 || u == 0x7F || std::string_view("<>:\"|$%").find(c) != std::string_view::npos) c = '_';
    }
    while (!segment.empty() && (segment.back() == '.' || segment.back() == ' ')) segment.pop_back();
    if (segment.size() > 200) {  // keep the end (the extension), cut on a UTF-8 character boundary
      std::size_t start = segment.size() - 200;
      while (start < segment.size() && (static_cast<unsigned char>(segment[start]) & 0xC0) == 0x80) ++start;
      segment = segment.substr(start);
    }
    if (segment.empty() || segment == "~" || IsReservedName(segment)) segment = "_" + segment;
    out += (out.empty() ? "" : "/") + segment;
  }
  if (out.empty()) out = "file";
  return out;
}

bool IsValidUtf8(std::string_view s) {
  std::size_t i = 0;
  while (i < s.size()) {
    const auto c = static_cast<unsigned char>(s[i]);
    int extra = 0;
    std::uint32_t cp = 0;
    if (c < 0x80) {
      ++i;
      continue;
    } else if ((c & 0xE0) == 0xC0) {
      extra = 1;
      cp = c & 0x1F;
    } else if ((c & 0xF0) == 0xE0) {
      extra = 2;
      cp = c & 0x0F;
    } else if ((c & 0xF8) == 0xF0) {
      extra = 3;
      cp = c & 0x07;
    } else {
      return false;
    }
    if (i + extra >= s.size()) return false;  // truncated sequence
    for (int k = 1; k <= extra; ++k) {
      const auto cc = static_cast<unsigned char>(s[i + k]);
      if ((cc & 0xC0) != 0x80) return false;
      cp = (cp << 6) | (cc & 0x3F);
    }
    // Overlong forms, UTF-16 surrogates and code points past U+10FFFF are not UTF-8.
    static constexpr std::uint32_t kMinForLength[4] = {0, 0x80, 0x800, 0x10000};
    if (cp < kMinForLength[extra] || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) return false;
    i += static_cast<std::size_t>(extra) + 1;
  }
  return true;
}

}  // namespace u3mscan
