#include "u3m/relative_path.h"

#include <algorithm>
#include <cctype>
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

constexpr std::size_t kMaxPathChars = 1024;

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

}  // namespace

RelativePathCheck CheckRelativePath(std::string_view path) {
  RelativePathCheck check;
  const auto refuse = [&](std::string reason) {
    check.unsafe = true;
    check.unsafe_reason = std::move(reason);
    return check;
  };
  if (path.empty()) return refuse("an empty path names no file");
  if (path.size() > kMaxPathChars) return refuse("a path longer than " + std::to_string(kMaxPathChars) + " characters");
  for (unsigned char c : path)
    if (c < 0x20 || c == 0x7F) return refuse("a control character in the path");
  if (path.find('\\') != std::string_view::npos) check.repairs.push_back("backslashes replaced by '/'");
  if (path.front() == '/' || path.front() == '\\') return refuse("an absolute path");
  if (HasDriveLetter(path)) return refuse("a drive letter");
  std::vector<std::string> kept;
  bool dropped = false;
  for (std::string& segment : Split(path, /*backslash_too=*/true)) {
    if (segment == "..") return refuse("a '..' segment that leaves the material's folder");
    if (segment.empty() || segment == ".") {
      dropped = true;
      continue;
    }
    if (segment.find(':') != std::string::npos) return refuse("a ':' (drive or stream name)");
    kept.push_back(std::move(segment));
  }
  if (kept.empty()) return refuse("a path that names no file");
  if (dropped) check.repairs.push_back("'.' and empty segments removed");
  for (std::size_t i = 0; i < kept.size(); ++i) check.normalized += (i ? "/" : "") + kept[i];
  std::string why;
  if (!IsWritableRelativePath(check.normalized, &why)) check.problems.push_back(why);
  return check;
}

bool IsWritableRelativePath(std::string_view path, std::string* why) {
  const auto fail = [&](const char* reason) {
    if (why) *why = reason;
    return false;
  };
  if (path.empty()) return fail("empty path");
  if (path.size() > kMaxPathChars) return fail("path too long");
  if (path.find('\\') != std::string_view::npos) return fail("backslash in path");
  if (path.front() == '/') return fail("absolute path");
  if (HasDriveLetter(path)) return fail("drive letter in path");
  for (const std::string& segment : Split(path, false)) {
    if (segment.empty()) return fail("empty path segment");
    if (segment == "." || segment == "..") return fail("'.' or '..' segment");
    if (segment.back() == '.' || segment.back() == ' ') return fail("segment ends with a dot or a space");
    if (IsReservedName(segment)) return fail("reserved device name (CON, NUL, COM1, ...)");
  }
  if (!std::regex_match(path.begin(), path.end(), SchemaPathPattern()))
    return fail("characters the 1.1 relative_file_path pattern forbids (<>:\"|\\, and $% in folder names)");
  return true;
}

std::string SanitizeRelativePath(std::string_view path) {
  std::string out;
  for (std::string segment : Split(path, true)) {
    if (segment.empty() || segment == "." || segment == "..") continue;
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

}  // namespace u3mscan
