#include "u3m/u3ma_archive.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <random>
#include <set>
#include <system_error>

#include "core/error.h"
#include "core/logging.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

// ZIP record layout: PKWARE APPNOTE 6.3.x, sections 4.3.7 (local header), 4.3.9 (data descriptor),
// 4.3.12 (central directory header), 4.3.16 (end of central directory record).
constexpr std::uint32_t kLocalSignature = 0x04034b50;
constexpr std::uint32_t kCentralSignature = 0x02014b50;
constexpr std::uint32_t kEndSignature = 0x06054b50;
constexpr std::uint32_t kDescriptorSignature = 0x08074b50;
constexpr std::uint32_t kZip64LocatorSignature = 0x07064b50;
constexpr std::size_t kLocalHeaderSize = 30;
constexpr std::size_t kCentralHeaderSize = 46;
constexpr std::size_t kEndRecordSize = 22;
constexpr std::size_t kZip64LocatorSize = 20;
constexpr std::size_t kMaxCommentSize = 0xFFFF;

constexpr std::uint16_t kVersionMadeBy = 0x003F;  // host 0 (MS-DOS), APPNOTE 6.3
constexpr std::uint16_t kVersionNeeded = 0x0014;  // 2.0: deflate and folders
constexpr std::uint16_t kMethodStore = 0;
constexpr std::uint16_t kMethodDeflate = 8;
constexpr std::uint16_t kMethodAes = 99;

constexpr std::uint16_t kFlagEncrypted = 1u << 0;
constexpr std::uint16_t kFlagDeflateOptions = (1u << 1) | (1u << 2);  // deflate level hints
constexpr std::uint16_t kFlagDescriptor = 1u << 3;
constexpr std::uint16_t kFlagPatched = 1u << 5;
constexpr std::uint16_t kFlagStrongEncryption = 1u << 6;
constexpr std::uint16_t kFlagUtf8 = 1u << 11;
constexpr std::uint16_t kFlagMaskedHeaders = 1u << 13;

constexpr std::uint32_t kUnixTypeMask = 0170000;
constexpr std::uint32_t kUnixRegular = 0100000;
constexpr std::uint32_t kUnixDirectory = 0040000;
constexpr std::uint32_t kUnixSymlink = 0120000;
constexpr std::uint32_t kDosDirectory = 0x10;
constexpr std::uint32_t kDosReparsePoint = 0x400;  // NTFS symlinks and junctions

// Room for headers, names and descriptors on top of the uncompressed bytes when deciding whether
// a file is too large to be read into memory at all.
constexpr std::uint64_t kArchiveOverheadBytes = std::uint64_t{64} << 20;

std::uint16_t Get16(std::span<const std::uint8_t> b, std::size_t pos) {
  return static_cast<std::uint16_t>(b[pos] | (b[pos + 1] << 8));
}
std::uint32_t Get32(std::span<const std::uint8_t> b, std::size_t pos) {
  return static_cast<std::uint32_t>(b[pos]) | (static_cast<std::uint32_t>(b[pos + 1]) << 8) |
         (static_cast<std::uint32_t>(b[pos + 2]) << 16) | (static_cast<std::uint32_t>(b[pos + 3]) << 24);
}
void Put16(std::vector<std::uint8_t>& out, std::uint32_t v) {
  out.push_back(static_cast<std::uint8_t>(v & 0xFF));
  out.push_back(static_cast<std::uint8_t>((v >> 8) & 0xFF));
}
void Put32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  Put16(out, v & 0xFFFF);
  Put16(out, v >> 16);
}

std::uint32_t Crc32(std::span<const std::uint8_t> data) {
  return static_cast<std::uint32_t>(crc32_z(crc32_z(0, nullptr, 0), data.data(), data.size()));
}

std::string Hex(std::uint32_t v) {
  char text[16];
  std::snprintf(text, sizeof(text), "0x%08x", v);
  return text;
}

// --- Names ------------------------------------------------------------------------------------

void AppendUtf8(std::string& out, std::uint32_t cp) {
  if (cp < 0x80) {
    out.push_back(static_cast<char>(cp));
  } else if (cp < 0x800) {
    out.push_back(static_cast<char>(0xC0 | (cp >> 6)));
    out.push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  } else {
    out.push_back(static_cast<char>(0xE0 | (cp >> 12)));
    out.push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3F)));
    out.push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  }
}

// Names without the UTF-8 flag are IBM code page 437 by the ZIP specification (APPNOTE D.1).
std::string Cp437ToUtf8(std::string_view raw) {
  static constexpr std::uint16_t kHigh[128] = {
      0x00C7, 0x00FC, 0x00E9, 0x00E2, 0x00E4, 0x00E0, 0x00E5, 0x00E7, 0x00EA, 0x00EB, 0x00E8, 0x00EF, 0x00EE,
      0x00EC, 0x00C4, 0x00C5, 0x00C9, 0x00E6, 0x00C6, 0x00F4, 0x00F6, 0x00F2, 0x00FB, 0x00F9, 0x00FF, 0x00D6,
      0x00DC, 0x00A2, 0x00A3, 0x00A5, 0x20A7, 0x0192, 0x00E1, 0x00ED, 0x00F3, 0x00FA, 0x00F1, 0x00D1, 0x00AA,
      0x00BA, 0x00BF, 0x2310, 0x00AC, 0x00BD, 0x00BC, 0x00A1, 0x00AB, 0x00BB, 0x2591, 0x2592, 0x2593, 0x2502,
      0x2524, 0x2561, 0x2562, 0x2556, 0x2555, 0x2563, 0x2551, 0x2557, 0x255D, 0x255C, 0x255B, 0x2510, 0x2514,
      0x2534, 0x252C, 0x251C, 0x2500, 0x253C, 0x255E, 0x255F, 0x255A, 0x2554, 0x2569, 0x2566, 0x2560, 0x2550,
      0x256C, 0x2567, 0x2568, 0x2564, 0x2565, 0x2559, 0x2558, 0x2552, 0x2553, 0x256B, 0x256A, 0x2518, 0x250C,
      0x2588, 0x2584, 0x258C, 0x2590, 0x2580, 0x03B1, 0x00DF, 0x0393, 0x03C0, 0x03A3, 0x03C3, 0x00B5, 0x03C4,
      0x03A6, 0x0398, 0x03A9, 0x03B4, 0x221E, 0x03C6, 0x03B5, 0x2229, 0x2261, 0x00B1, 0x2265, 0x2264, 0x2320,
      0x2321, 0x00F7, 0x2248, 0x00B0, 0x2219, 0x00B7, 0x221A, 0x207F, 0x00B2, 0x25A0, 0x00A0};
  std::string out;
  for (char ch : raw) {
    const auto c = static_cast<unsigned char>(ch);
    AppendUtf8(out, c < 0x80 ? c : kHigh[c - 0x80]);
  }
  return out;
}

// Printable form of a name for messages: control bytes become \xNN so a hostile name cannot
// rewrite the terminal.
std::string Printable(std::string_view raw) {
  std::string out;
  for (char ch : raw) {
    const auto c = static_cast<unsigned char>(ch);
    if (c < 0x20 || c == 0x7F) {
      char buf[8];
      std::snprintf(buf, sizeof(buf), "\\x%02x", c);
      out += buf;
    } else {
      out.push_back(ch);
    }
  }
  return "\"" + out + "\"";
}

static_assert(kMaxRelativePathBytes <= 0xFFFF, "a ZIP name length is 16 bits: every checked name fits");

// An entry name by the project's one path rule (u3m/relative_path.h), in its exact spelling: what
// lands on disk is the name as written, so slips a U3M reader would repair are refused here.
struct NameCheck {
  std::string error;    // could escape or confuse the output (expected ...): refuse
  std::string warning;  // breaks the conventions or the 1.1 pattern (what it has): refuse on write, warn on read
};

NameCheck CheckName(std::string_view name) {
  const RelativePathCheck check = CheckRelativePath(name, PathSpelling::kExact);
  if (check.unsafe) return {check.unsafe_reason, ""};
  return {"", check.problems.empty() ? "" : check.problems.front()};
}

std::string FoldAscii(std::string_view s) {
  std::string out(s);
  for (char& c : out) {
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  }
  return out;
}

// A file "a" and a file "a/b" cannot both be unpacked; returns the clash or "".
std::string FileFolderClash(const std::set<std::string>& files, const std::set<std::string>& folders) {
  for (const std::string& name : files) {
    if (folders.count(name)) return name;
    for (std::size_t slash = name.find('/'); slash != std::string::npos; slash = name.find('/', slash + 1)) {
      if (files.count(name.substr(0, slash))) return name.substr(0, slash);
    }
  }
  return "";
}

// --- DOS time ---------------------------------------------------------------------------------

// DOS date/time of a UTC instant (2-second resolution), clamped to the range DOS can hold.
void ToDosTime(std::time_t utc, std::uint16_t* dos_time, std::uint16_t* dos_date) {
  std::tm t{};
  if (!gmtime_r(&utc, &t) || t.tm_year < 80) {
    t = std::tm{};
    t.tm_year = 80;
    t.tm_mday = 1;
  } else if (t.tm_year > 80 + 127) {
    t.tm_year = 80 + 127;
    t.tm_mon = 11;
    t.tm_mday = 31;
    t.tm_hour = 23;
    t.tm_min = 59;
    t.tm_sec = 58;
  }
  const int seconds = std::min(t.tm_sec, 59);  // a leap second rounds down
  *dos_time = static_cast<std::uint16_t>((t.tm_hour << 11) | (t.tm_min << 5) | (seconds / 2));
  *dos_date = static_cast<std::uint16_t>(((t.tm_year - 80) << 9) | ((t.tm_mon + 1) << 5) | t.tm_mday);
}

// --- Deflate ----------------------------------------------------------------------------------

// Raw deflate (no zlib header), as ZIP method 8 stores it.
std::vector<std::uint8_t> Deflate(std::span<const std::uint8_t> data) {
  z_stream zs{};
  if (deflateInit2(&zs, Z_DEFAULT_COMPRESSION, Z_DEFLATED, -15, 8, Z_DEFAULT_STRATEGY) != Z_OK) {
    throw std::runtime_error("zlib deflateInit2 failed");
  }
  std::vector<std::uint8_t> out(deflateBound(&zs, static_cast<uLong>(data.size())));
  zs.next_in = const_cast<Bytef*>(data.data());
  zs.avail_in = static_cast<uInt>(data.size());
  zs.next_out = out.data();
  zs.avail_out = static_cast<uInt>(out.size());
  const int ret = deflate(&zs, Z_FINISH);
  const std::size_t produced = zs.total_out;
  deflateEnd(&zs);
  if (ret != Z_STREAM_END) throw std::runtime_error("zlib deflate did not finish within deflateBound");
  out.resize(produced);
  return out;
}

// PNG, TIFF (zip) and EXR textures are compressed already. A trial on the first kTrialBytes
// decides, from the data alone (so output stays reproducible), whether deflating the whole entry
// can pay: it must save at least 1 % there.
bool WorthDeflating(std::span<const std::uint8_t> data) {
  constexpr std::size_t kTrialBytes = std::size_t{256} << 10;
  constexpr double kMinSaving = 0.01;
  if (data.size() <= kTrialBytes) return true;
  const std::size_t trial = Deflate(data.first(kTrialBytes)).size();
  return static_cast<double>(trial) < (1.0 - kMinSaving) * kTrialBytes;
}

// --- Reading ----------------------------------------------------------------------------------

struct CentralEntry {
  std::size_t index = 0;
  std::string raw_name;  // bytes as stored, to compare with the local header
  std::string name;      // UTF-8
  bool folder = false;
  std::uint16_t made_by = 0;
  std::uint16_t needed = 0;
  std::uint16_t flags = 0;
  std::uint16_t method = 0;
  std::uint16_t dos_time = 0;
  std::uint16_t dos_date = 0;
  std::uint32_t crc = 0;
  std::uint32_t compressed = 0;
  std::uint32_t uncompressed = 0;
  std::uint32_t local_offset = 0;
  std::uint64_t data_begin = 0;
  std::uint64_t span_end = 0;  // end of data and data descriptor
};

class ArchiveParser {
 public:
  ArchiveParser(std::span<const std::uint8_t> bytes, const std::string& archive, const ArchiveLimits& limits,
                std::vector<std::string>* warnings)
      : b_(bytes), archive_(archive), limits_(limits), warnings_(warnings) {}

  std::vector<ArchiveEntry> Parse() {
    const std::size_t end_pos = FindEndRecord();
    ParseEndRecord(end_pos);
    ParseCentralDirectory();
    CheckNamesAndLimits();
    for (CentralEntry& e : entries_) CheckLocalHeader(e);
    CheckCoverage();
    std::vector<ArchiveEntry> out;
    out.reserve(entries_.size());
    for (const CentralEntry& e : entries_) {
      std::vector<std::uint8_t> data = Unpack(e);
      if (e.folder) continue;
      out.push_back({e.name, std::move(data)});
    }
    EmitWarnings();
    return out;
  }

 private:
  [[noreturn]] void Fail(const std::string& where, const std::string& expected) const {
    throw InputError(archive_, where, expected);
  }
  static std::string EntryLabel(const CentralEntry& e) {
    return e.name.empty() ? "central directory entry #" + std::to_string(e.index + 1) : "entry " + Printable(e.name);
  }
  void Warn(const std::string& kind, const std::string& entry) {
    for (auto& w : pending_) {
      if (w.kind == kind) {
        ++w.count;
        return;
      }
    }
    pending_.push_back({kind, entry, 1});
  }
  void EmitWarnings() {
    for (const auto& w : pending_) {
      std::string message = archive_ + ": " + w.kind;
      if (!w.first_entry.empty()) {
        message += " (" + w.first_entry;
        if (w.count > 1) message += " and " + std::to_string(w.count - 1) + " more";
        message += ")";
      }
      message += "; read anyway";
      if (warnings_) {
        warnings_->push_back(message);
      } else {
        LogWarning() << message;
      }
    }
  }

  std::size_t FindEndRecord() {
    const std::size_t size = b_.size();
    if (size < kEndRecordSize) {
      Fail("end record", "a ZIP archive of at least 22 bytes, got " + std::to_string(size));
    }
    const std::size_t lowest = size - kEndRecordSize > kMaxCommentSize ? size - kEndRecordSize - kMaxCommentSize : 0;
    bool signature_seen = false;
    for (std::size_t pos = size - kEndRecordSize + 1; pos-- > lowest;) {
      if (Get32(b_, pos) != kEndSignature) continue;
      signature_seen = true;
      if (pos + kEndRecordSize + Get16(b_, pos + 20) == size) return pos;
    }
    if (signature_seen) {
      Fail("end record", "nothing after the end record and its comment (the file has trailing bytes or is cut)");
    }
    Fail("end record", "a ZIP end-of-central-directory record (signature PK\\5\\6) in the last 64 KiB; "
                       "not a ZIP archive, or truncated");
  }

  void ParseEndRecord(std::size_t pos) {
    end_pos_ = pos;
    const std::uint16_t disk = Get16(b_, pos + 4);
    const std::uint16_t cd_disk = Get16(b_, pos + 6);
    const std::uint16_t entries_here = Get16(b_, pos + 8);
    const std::uint16_t entries_total = Get16(b_, pos + 10);
    cd_size_ = Get32(b_, pos + 12);
    cd_offset_ = Get32(b_, pos + 16);
    const std::uint16_t comment = Get16(b_, pos + 20);
    if (pos >= kZip64LocatorSize && Get32(b_, pos - kZip64LocatorSize) == kZip64LocatorSignature) {
      Fail("end record", "no zip64 records (this archive has a zip64 locator)");
    }
    if (entries_total == 0xFFFF || cd_size_ == 0xFFFFFFFF || cd_offset_ == 0xFFFFFFFF) {
      Fail("end record", "no zip64 (the end record holds zip64 placeholders)");
    }
    if (disk != 0 || cd_disk != 0 || entries_here != entries_total) {
      Fail("end record", "a single-disk archive (disk " + std::to_string(disk) + ", central directory on disk " +
                             std::to_string(cd_disk) + ")");
    }
    if (entries_total > limits_.max_entries) {
      Fail("end record", "at most " + std::to_string(limits_.max_entries) + " entries, got " +
                             std::to_string(entries_total));
    }
    if (static_cast<std::uint64_t>(cd_offset_) + cd_size_ != pos) {
      Fail("end record", "a central directory ending at the end record (offset " + std::to_string(cd_offset_) +
                             " + size " + std::to_string(cd_size_) + " != " + std::to_string(pos) +
                             "); the archive is truncated, padded or has data before it");
    }
    if (static_cast<std::uint64_t>(entries_total) * kCentralHeaderSize > cd_size_) {
      Fail("end record", std::to_string(entries_total) + " entries in a central directory of " +
                             std::to_string(cd_size_) + " bytes (each needs 46)");
    }
    if (comment != 0) Warn("has an archive comment", "");
    entry_count_ = entries_total;
  }

  void ParseCentralDirectory() {
    std::size_t pos = cd_offset_;
    const std::size_t cd_end = end_pos_;
    entries_.reserve(entry_count_);
    for (std::size_t i = 0; i < entry_count_; ++i) {
      CentralEntry e;
      e.index = i;
      if (pos + kCentralHeaderSize > cd_end || Get32(b_, pos) != kCentralSignature) {
        Fail(EntryLabel(e), "a central directory header (signature PK\\1\\2) at offset " + std::to_string(pos));
      }
      e.made_by = Get16(b_, pos + 4);
      e.needed = Get16(b_, pos + 6);
      e.flags = Get16(b_, pos + 8);
      e.method = Get16(b_, pos + 10);
      e.dos_time = Get16(b_, pos + 12);
      e.dos_date = Get16(b_, pos + 14);
      e.crc = Get32(b_, pos + 16);
      e.compressed = Get32(b_, pos + 20);
      e.uncompressed = Get32(b_, pos + 24);
      const std::uint16_t name_len = Get16(b_, pos + 28);
      const std::uint16_t extra_len = Get16(b_, pos + 30);
      const std::uint16_t comment_len = Get16(b_, pos + 32);
      const std::uint16_t disk_start = Get16(b_, pos + 34);
      const std::uint32_t external = Get32(b_, pos + 38);
      e.local_offset = Get32(b_, pos + 42);
      const std::size_t var_end = pos + kCentralHeaderSize + name_len + extra_len + comment_len;
      if (var_end > cd_end) {
        Fail(EntryLabel(e), "name, extra field and comment inside the central directory (they run " +
                                std::to_string(var_end - cd_end) + " bytes past it)");
      }
      e.raw_name.assign(reinterpret_cast<const char*>(b_.data() + pos + kCentralHeaderSize), name_len);
      e.name = DecodeName(e);
      CheckExtraField(e, pos + kCentralHeaderSize + name_len, extra_len, "central");
      if (comment_len != 0) Warn("has entry comments", EntryLabel(e));

      const std::string label = EntryLabel(e);
      if (disk_start != 0) Fail(label, "an entry on disk 0, got disk " + std::to_string(disk_start));
      if (e.flags & (kFlagEncrypted | kFlagStrongEncryption | kFlagMaskedHeaders) || e.method == kMethodAes) {
        Fail(label, "an unencrypted entry (general purpose flags " + Hex(e.flags) + ", method " +
                        std::to_string(e.method) + ")");
      }
      if (e.flags & kFlagPatched) Fail(label, "no patched data (flag bit 5)");
      if (e.method != kMethodStore && e.method != kMethodDeflate) {
        Fail(label, "compression method 0 (store) or 8 (deflate), got " + std::to_string(e.method));
      }
      if (e.compressed == 0xFFFFFFFF || e.uncompressed == 0xFFFFFFFF || e.local_offset == 0xFFFFFFFF) {
        Fail(label, "no zip64 (sizes or offset are zip64 placeholders)");
      }
      if (e.method == kMethodStore && e.compressed != e.uncompressed) {
        Fail(label, "equal sizes for a stored entry, got compressed " + std::to_string(e.compressed) +
                        " and uncompressed " + std::to_string(e.uncompressed));
      }
      const std::uint16_t known = kFlagDeflateOptions | kFlagDescriptor | kFlagUtf8;
      if (e.flags & ~known) Warn("sets unknown general purpose flag bits", label);
      if (e.flags & kFlagDescriptor) Warn("uses data descriptors", label);
      if (e.made_by != kVersionMadeBy) Warn("has a version-made-by other than 0x003F", label);
      if (e.needed > 20) Warn("asks for a reader version above 2.0 but uses only store/deflate", label);
      CheckAttributes(e, external);
      entries_.push_back(std::move(e));
      pos = var_end;
    }
    if (pos != cd_end) {
      Fail("central directory", "exactly " + std::to_string(entry_count_) + " headers filling " +
                                    std::to_string(cd_size_) + " bytes; " + std::to_string(cd_end - pos) +
                                    " bytes are left over");
    }
  }

  std::string DecodeName(const CentralEntry& e) {
    const std::string& raw = e.raw_name;
    const std::string label = "central directory entry #" + std::to_string(e.index + 1);
    if (raw.find('\0') != std::string::npos) Fail(label, "a name without NUL bytes, got " + Printable(raw));
    if (e.flags & kFlagUtf8) {
      if (!IsValidUtf8(raw)) Fail(label, "a valid UTF-8 name (the UTF-8 flag is set), got " + Printable(raw));
      return raw;
    }
    const bool ascii = std::all_of(raw.begin(), raw.end(), [](char c) { return static_cast<unsigned char>(c) < 0x80; });
    if (ascii) return raw;
    if (IsValidUtf8(raw)) {
      Warn("has non-ASCII names without the UTF-8 flag; taken as UTF-8", "entry " + Printable(raw));
      return raw;
    }
    std::string name = Cp437ToUtf8(raw);
    Warn("has non-ASCII names without the UTF-8 flag; taken as code page 437", "entry " + Printable(name));
    return name;
  }

  // Extra fields are (id, size, data) records that must exactly fill their area. We use none of
  // them: sizes come from the headers, and zip64 is refused where it would matter.
  void CheckExtraField(const CentralEntry& e, std::size_t pos, std::size_t len, const char* where) {
    const std::size_t end = pos + len;
    while (pos < end) {
      if (pos + 4 > end || pos + 4 + Get16(b_, pos + 2) > end) {
        Fail(EntryLabel(e), std::string("a well-formed extra field in the ") + where + " header");
      }
      pos += 4 + Get16(b_, pos + 2);
    }
    if (len != 0) Warn("carries extra fields (ignored)", EntryLabel(e));
  }

  void CheckAttributes(CentralEntry& e, std::uint32_t external) {
    const std::string label = EntryLabel(e);
    const unsigned host = e.made_by >> 8;
    const bool name_is_folder = !e.name.empty() && e.name.back() == '/';
    bool folder_attr = false;
    if (host == 3 || host == 19) {  // Unix, OS X: st_mode in the high 16 bits
      const std::uint32_t type = (external >> 16) & kUnixTypeMask;
      if (type == kUnixSymlink) Fail(label, "a regular file, not a symbolic link");
      if (type != 0 && type != kUnixRegular && type != kUnixDirectory) {
        Fail(label, "a regular file or folder, got Unix file type " + Hex(type));
      }
      folder_attr = type == kUnixDirectory;
    }
    if (external & kDosReparsePoint) Fail(label, "a regular file, not a reparse point (symbolic link)");
    folder_attr = folder_attr || (external & kDosDirectory);
    if (folder_attr && !name_is_folder) Fail(label, "a folder entry's name to end in '/'");
    if (external != 0) Warn("has external attributes other than 0", label);
    e.folder = name_is_folder;
  }

  void CheckNamesAndLimits() {
    std::set<std::string> names, files, folders;
    std::map<std::string, std::string> folded;
    std::uint64_t total = 0;
    for (const CentralEntry& e : entries_) {
      const std::string label = EntryLabel(e);
      std::string_view checked = e.name;
      if (e.folder) checked.remove_suffix(1);
      const NameCheck check = CheckName(checked);
      if (!check.error.empty()) Fail(label, check.error);
      if (!check.warning.empty()) Warn("has names the conventions advise against: " + check.warning, label);
      if (!names.insert(e.name).second) Fail(label, "a unique name; it appears twice");
      (e.folder ? folders : files).insert(std::string(checked));
      if (!e.folder) {
        auto [it, inserted] = folded.emplace(FoldAscii(e.name), e.name);
        if (!inserted) Warn("has names that differ only in case (they collide on Windows and macOS)", label);
      }
      if (e.folder && e.uncompressed != 0) {
        Fail(label, "an empty folder entry, got " + std::to_string(e.uncompressed) + " bytes");
      }
      // Zip-bomb guards on the declared sizes, before a single byte is inflated.
      if (e.uncompressed > limits_.max_entry_bytes) {
        Fail(label, "at most " + std::to_string(limits_.max_entry_bytes) + " uncompressed bytes per entry, declared " +
                        std::to_string(e.uncompressed));
      }
      total += e.uncompressed;
      if (total > limits_.max_total_bytes) {
        Fail(label, "at most " + std::to_string(limits_.max_total_bytes) +
                        " uncompressed bytes in all, the entries up to this one declare " + std::to_string(total));
      }
      const double ratio = static_cast<double>(e.uncompressed) / std::max<std::uint32_t>(e.compressed, 1);
      if (ratio > limits_.max_compression_ratio) {
        Fail(label, "a compression ratio of at most " + std::to_string(limits_.max_compression_ratio) +
                        ", declared " + std::to_string(e.uncompressed) + " from " + std::to_string(e.compressed) +
                        " bytes (zip bomb?)");
      }
    }
    const std::string clash = FileFolderClash(files, folders);
    if (!clash.empty()) Fail("entry " + Printable(clash), "a name that is not both a file and a folder");
  }

  void CheckLocalHeader(CentralEntry& e) {
    const std::string label = EntryLabel(e);
    const std::uint64_t pos = e.local_offset;
    if (pos + kLocalHeaderSize > cd_offset_ || Get32(b_, pos) != kLocalSignature) {
      Fail(label, "a local header (signature PK\\3\\4) at offset " + std::to_string(pos) +
                      " before the central directory");
    }
    const std::uint16_t needed = Get16(b_, pos + 4);
    const std::uint16_t flags = Get16(b_, pos + 6);
    const std::uint16_t method = Get16(b_, pos + 8);
    const std::uint16_t dos_time = Get16(b_, pos + 10);
    const std::uint16_t dos_date = Get16(b_, pos + 12);
    const std::uint32_t crc = Get32(b_, pos + 14);
    const std::uint32_t compressed = Get32(b_, pos + 18);
    const std::uint32_t uncompressed = Get32(b_, pos + 22);
    const std::uint16_t name_len = Get16(b_, pos + 26);
    const std::uint16_t extra_len = Get16(b_, pos + 28);
    const std::uint64_t data_begin = pos + kLocalHeaderSize + name_len + extra_len;
    if (data_begin > cd_offset_) Fail(label, "a local header that ends before the central directory");
    const std::string_view local_name(reinterpret_cast<const char*>(b_.data() + pos + kLocalHeaderSize), name_len);
    if (local_name != e.raw_name) {
      Fail(label, "the same name in the local header as in the central directory, got " + Printable(local_name));
    }
    CheckExtraField(e, pos + kLocalHeaderSize + name_len, extra_len, "local");
    const std::uint16_t must_match = kFlagEncrypted | kFlagDescriptor | kFlagUtf8 | kFlagStrongEncryption;
    if ((flags & must_match) != (e.flags & must_match)) {
      Fail(label, "local header flags " + Hex(flags) + " agreeing with the central directory's " + Hex(e.flags));
    }
    if (flags != e.flags) Warn("has local flags that differ from the central directory in minor bits", label);
    if (method != e.method) {
      Fail(label, "the same method in the local header (" + std::to_string(method) + ") as in the central directory (" +
                      std::to_string(e.method) + ")");
    }
    if (needed != e.needed || dos_time != e.dos_time || dos_date != e.dos_date) {
      Warn("has local version or time fields that differ from the central directory", label);
    }
    const bool descriptor = e.flags & kFlagDescriptor;
    auto agrees = [&](std::uint32_t local, std::uint32_t central) {
      return local == central || (descriptor && local == 0);
    };
    if (!agrees(crc, e.crc) || !agrees(compressed, e.compressed) || !agrees(uncompressed, e.uncompressed)) {
      Fail(label, "local CRC and sizes (" + Hex(crc) + ", " + std::to_string(compressed) + ", " +
                      std::to_string(uncompressed) + ") agreeing with the central directory (" + Hex(e.crc) + ", " +
                      std::to_string(e.compressed) + ", " + std::to_string(e.uncompressed) + ")");
    }
    e.data_begin = data_begin;
    const std::uint64_t data_end = data_begin + e.compressed;
    if (data_end > cd_offset_) {
      Fail(label, std::to_string(e.compressed) + " bytes of data before the central directory; only " +
                      std::to_string(cd_offset_ - data_begin) + " are there (truncated or size lies)");
    }
    e.span_end = data_end;
    if (descriptor) {
      // Data descriptor: optional signature, then CRC, compressed and uncompressed size (APPNOTE 4.3.9).
      auto matches_at = [&](std::uint64_t p) {
        return p + 12 <= cd_offset_ && Get32(b_, p) == e.crc && Get32(b_, p + 4) == e.compressed &&
               Get32(b_, p + 8) == e.uncompressed;
      };
      if (data_end + 4 <= cd_offset_ && Get32(b_, data_end) == kDescriptorSignature && matches_at(data_end + 4)) {
        e.span_end = data_end + 16;
      } else if (matches_at(data_end)) {
        e.span_end = data_end + 12;
      } else {
        Fail(label, "a data descriptor after the data that agrees with the central directory");
      }
    }
  }

  // Every byte before the central directory belongs to exactly one entry: no prefix, no gaps, no
  // overlaps (overlapping entries are how "quines" and overlap bombs multiply their output).
  void CheckCoverage() {
    std::vector<const CentralEntry*> order;
    for (const CentralEntry& e : entries_) order.push_back(&e);
    std::sort(order.begin(), order.end(),
              [](const CentralEntry* a, const CentralEntry* b) { return a->local_offset < b->local_offset; });
    std::uint64_t expected = 0;
    const CentralEntry* previous = nullptr;
    for (const CentralEntry* e : order) {
      if (e->local_offset < expected) {
        Fail(EntryLabel(*e), "an entry that does not overlap " + EntryLabel(*previous) + " (it starts at offset " +
                                 std::to_string(e->local_offset) + ", the other ends at " + std::to_string(expected) +
                                 ")");
      }
      if (e->local_offset > expected) {
        Fail(EntryLabel(*e), "entries packed one after the other from offset 0; " +
                                 std::to_string(e->local_offset - expected) + " unclaimed bytes precede it");
      }
      expected = e->span_end;
      previous = e;
    }
    if (expected != cd_offset_) {
      Fail("central directory", "to start right after the last entry (offset " + std::to_string(expected) +
                                    "), it starts at " + std::to_string(cd_offset_));
    }
  }

  std::vector<std::uint8_t> Unpack(const CentralEntry& e) {
    const std::string label = EntryLabel(e);
    const std::span<const std::uint8_t> packed = b_.subspan(e.data_begin, e.compressed);
    std::vector<std::uint8_t> data;
    if (e.method == kMethodStore) {
      data.assign(packed.begin(), packed.end());
    } else {
      data.resize(e.uncompressed);
      z_stream zs{};
      if (inflateInit2(&zs, -15) != Z_OK) throw std::runtime_error("zlib inflateInit2 failed");
      zs.next_in = const_cast<Bytef*>(packed.data());
      zs.avail_in = static_cast<uInt>(packed.size());
      zs.next_out = data.data();
      zs.avail_out = static_cast<uInt>(data.size());
      // Inflate into exactly the declared size; one spare byte detects a stream that would go on.
      std::uint8_t spare = 0;
      bool spare_in_use = false;
      std::string error;
      for (;;) {
        const uLong in_before = zs.total_in, out_before = zs.total_out;
        const int ret = inflate(&zs, Z_NO_FLUSH);
        if (ret == Z_STREAM_END) break;
        if (ret != Z_OK && ret != Z_BUF_ERROR) {
          error = std::string("valid deflate data (") + (zs.msg ? zs.msg : "zlib error " + std::to_string(ret)) + ")";
          break;
        }
        if (zs.avail_out == 0) {
          if (spare_in_use) break;  // produced a byte past the declared size
          spare_in_use = true;
          zs.next_out = &spare;
          zs.avail_out = 1;
          continue;
        }
        if (zs.avail_in == 0) {
          error = "deflate data that ends within the compressed size " + std::to_string(e.compressed) +
                  " (truncated)";
          break;
        }
        if (zs.total_in == in_before && zs.total_out == out_before) {
          error = "deflate data that makes progress";
          break;
        }
      }
      const std::uint64_t produced = zs.total_out;
      const std::uint64_t consumed = zs.total_in;
      inflateEnd(&zs);
      if (!error.empty()) Fail(label, error);
      if (produced > e.uncompressed) {
        Fail(label, "no more than the declared " + std::to_string(e.uncompressed) +
                        " uncompressed bytes; the data goes on (size lie or zip bomb), inflating stopped");
      }
      if (produced != e.uncompressed) {
        Fail(label, "the declared " + std::to_string(e.uncompressed) + " uncompressed bytes, the data holds " +
                        std::to_string(produced));
      }
      if (consumed != e.compressed) {
        Fail(label, "deflate data filling the declared compressed size " + std::to_string(e.compressed) +
                        ", it ends after " + std::to_string(consumed));
      }
    }
    const std::uint32_t crc = Crc32(data);
    if (crc != e.crc) Fail(label, "CRC-32 " + Hex(e.crc) + " as declared, the data has " + Hex(crc));
    return data;
  }

  struct PendingWarning {
    std::string kind;
    std::string first_entry;
    std::size_t count = 0;
  };

  std::span<const std::uint8_t> b_;
  const std::string& archive_;
  const ArchiveLimits& limits_;
  std::vector<std::string>* warnings_;
  std::vector<CentralEntry> entries_;
  std::vector<PendingWarning> pending_;
  std::size_t end_pos_ = 0;
  std::size_t entry_count_ = 0;
  std::uint32_t cd_size_ = 0;
  std::uint32_t cd_offset_ = 0;
};

// --- Files ------------------------------------------------------------------------------------

std::string RandomSuffix() {
  static thread_local std::mt19937_64 rng{std::random_device{}()};
  static constexpr char kDigits[] = "0123456789abcdefghijklmnopqrstuvwxyz";
  std::string s;
  for (int i = 0; i < 10; ++i) s.push_back(kDigits[rng() % 36]);
  return s;
}

// Writes `bytes` to a new file beside `path` and renames it over `path`; the file is synced first
// so a crash leaves either the old file or the complete new one.
void WriteFileAtomically(const fs::path& path, std::span<const std::uint8_t> bytes, const std::string& what) {
  const fs::path dir = path.has_parent_path() ? path.parent_path() : fs::path(".");
  fs::path temp;
  int fd = -1;
  for (int attempt = 0; attempt < 16 && fd < 0; ++attempt) {
    temp = dir / ("." + path.filename().string() + ".partial-" + RandomSuffix());
    fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd < 0 && errno != EEXIST) break;
  }
  if (fd < 0) throw InputError(what, "", "a writable folder for a temporary file: " + std::string(std::strerror(errno)));
  std::size_t written = 0;
  std::string error;
  while (written < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + written, bytes.size() - written);
    if (n < 0) {
      if (errno == EINTR) continue;
      error = std::strerror(errno);
      break;
    }
    written += static_cast<std::size_t>(n);
  }
  if (error.empty() && ::fsync(fd) != 0) error = std::strerror(errno);
  if (::close(fd) != 0 && error.empty()) error = std::strerror(errno);
  if (error.empty()) {
    std::error_code ec;
    fs::rename(temp, path, ec);
    if (ec) error = "rename failed: " + ec.message();
  }
  if (!error.empty()) {
    std::error_code ignored;
    fs::remove(temp, ignored);
    throw InputError(what, "", "a location that can be written: " + error);
  }
}

std::vector<std::uint8_t> ReadWholeFile(const fs::path& path, std::uint64_t max_bytes) {
  std::error_code ec;
  const std::uint64_t size = fs::file_size(path, ec);
  if (ec) throw InputError(path.string(), "", "a readable archive file: " + ec.message());
  if (size > max_bytes) {
    throw InputError(path.string(), "", "an archive of at most " + std::to_string(max_bytes) + " bytes, got " +
                                            std::to_string(size));
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path.string(), "", "a readable archive file");
  std::vector<std::uint8_t> bytes(size);
  in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size));
  if (static_cast<std::uint64_t>(in.gcount()) != size) {
    throw InputError(path.string(), "", "an archive file that can be read to its end");
  }
  return bytes;
}

}  // namespace

std::vector<ArchiveEntry> ParseArchive(std::span<const std::uint8_t> bytes, const std::string& archive_name,
                                       const ArchiveLimits& limits, std::vector<std::string>* warnings) {
  return ArchiveParser(bytes, archive_name, limits, warnings).Parse();
}

std::vector<ArchiveEntry> ReadArchive(const fs::path& path, const ArchiveLimits& limits,
                                      std::vector<std::string>* warnings) {
  const std::uint64_t max_file = limits.max_total_bytes > UINT64_MAX - kArchiveOverheadBytes
                                     ? UINT64_MAX
                                     : limits.max_total_bytes + kArchiveOverheadBytes;
  const std::vector<std::uint8_t> bytes = ReadWholeFile(path, max_file);
  return ParseArchive(bytes, path.string(), limits, warnings);
}

std::vector<std::uint8_t> SerializeArchive(const std::vector<ArchiveEntry>& entries, const std::string& archive_name,
                                           const ArchiveWriteOptions& options) {
  // What we write must pass our own reader with default limits.
  const ArchiveLimits limits;
  if (entries.size() > limits.max_entries) {
    throw InputError(archive_name, "", "at most " + std::to_string(limits.max_entries) + " entries, got " +
                                           std::to_string(entries.size()));
  }
  std::set<std::string> names, folded, files;
  std::uint64_t total = 0;
  for (const ArchiveEntry& entry : entries) {
    const std::string label = "entry " + Printable(entry.name);
    const NameCheck check = CheckName(entry.name);
    if (!check.error.empty()) throw InputError(archive_name, label, check.error);
    if (!check.warning.empty()) throw InputError(archive_name, label, "a name the conventions allow, got " + check.warning);
    if (!names.insert(entry.name).second) throw InputError(archive_name, label, "a unique name; it appears twice");
    if (!folded.insert(FoldAscii(entry.name)).second) {
      throw InputError(archive_name, label, "a name unique also without regard to case");
    }
    files.insert(entry.name);
    if (entry.data.size() > limits.max_entry_bytes) {
      throw InputError(archive_name, label, "at most " + std::to_string(limits.max_entry_bytes) + " bytes");
    }
    total += entry.data.size();
    if (total > limits.max_total_bytes) {
      throw InputError(archive_name, label, "at most " + std::to_string(limits.max_total_bytes) + " bytes in all");
    }
  }
  const std::string clash = FileFolderClash(files, {});
  if (!clash.empty()) throw InputError(archive_name, "entry " + Printable(clash), "a name that is not both a file and a folder");

  std::uint16_t dos_time = 0, dos_date = 0;
  ToDosTime(options.modified_utc != 0 ? options.modified_utc : std::time(nullptr), &dos_time, &dos_date);

  std::vector<std::uint8_t> out;
  std::vector<std::uint8_t> central;
  for (const ArchiveEntry& entry : entries) {
    const std::uint32_t crc = Crc32(entry.data);
    std::uint16_t method = kMethodStore;
    std::vector<std::uint8_t> deflated;
    if (options.compression == ArchiveCompression::kDeflate && !entry.data.empty() && WorthDeflating(entry.data)) {
      deflated = Deflate(entry.data);
      const double ratio = static_cast<double>(entry.data.size()) / std::max<std::size_t>(deflated.size(), 1);
      if (deflated.size() < entry.data.size() && ratio <= limits.max_compression_ratio) method = kMethodDeflate;
    }
    const std::span<const std::uint8_t> payload =
        method == kMethodDeflate ? std::span<const std::uint8_t>(deflated) : std::span<const std::uint8_t>(entry.data);
    const std::uint64_t offset = out.size();
    if (offset + kLocalHeaderSize + entry.name.size() + payload.size() > 0xFFFFFFFEu) {
      throw InputError(archive_name, "entry " + Printable(entry.name), "an archive below 4 GiB (no zip64)");
    }
    auto put_common = [&](std::vector<std::uint8_t>& v) {
      Put16(v, kVersionNeeded);
      Put16(v, kFlagUtf8);
      Put16(v, method);
      Put16(v, dos_time);
      Put16(v, dos_date);
      Put32(v, crc);
      Put32(v, static_cast<std::uint32_t>(payload.size()));
      Put32(v, static_cast<std::uint32_t>(entry.data.size()));
      Put16(v, static_cast<std::uint32_t>(entry.name.size()));
      Put16(v, 0);  // extra field length
    };
    Put32(out, kLocalSignature);
    put_common(out);
    out.insert(out.end(), entry.name.begin(), entry.name.end());
    out.insert(out.end(), payload.begin(), payload.end());

    Put32(central, kCentralSignature);
    Put16(central, kVersionMadeBy);
    put_common(central);
    Put16(central, 0);  // comment length
    Put16(central, 0);  // disk number start
    Put16(central, 0);  // internal attributes
    Put32(central, 0);  // external attributes
    Put32(central, static_cast<std::uint32_t>(offset));
    central.insert(central.end(), entry.name.begin(), entry.name.end());
  }
  const std::uint64_t cd_offset = out.size();
  if (cd_offset + central.size() + kEndRecordSize > 0xFFFFFFFEu) {
    throw InputError(archive_name, "central directory", "an archive below 4 GiB (no zip64)");
  }
  out.insert(out.end(), central.begin(), central.end());
  Put32(out, kEndSignature);
  Put16(out, 0);  // this disk
  Put16(out, 0);  // disk with the central directory
  Put16(out, static_cast<std::uint32_t>(entries.size()));
  Put16(out, static_cast<std::uint32_t>(entries.size()));
  Put32(out, static_cast<std::uint32_t>(central.size()));
  Put32(out, static_cast<std::uint32_t>(cd_offset));
  Put16(out, 0);  // comment length
  return out;
}

void WriteArchive(const fs::path& path, const std::vector<ArchiveEntry>& entries, const ArchiveWriteOptions& options) {
  const std::vector<std::uint8_t> bytes = SerializeArchive(entries, path.string(), options);
  WriteFileAtomically(path, bytes, path.string());
}

std::vector<std::string> ExtractArchive(const fs::path& archive, const fs::path& out_dir, const ArchiveLimits& limits,
                                        std::vector<std::string>* warnings) {
  fs::path target = out_dir;
  if (!target.empty() && !target.has_filename()) target = target.parent_path();  // "out/" -> "out"
  if (target.empty()) throw InputError(out_dir.string(), "", "a folder name to extract into");
  std::error_code ec;
  if (fs::exists(target, ec)) {
    if (!fs::is_directory(target, ec) || !fs::is_empty(target, ec)) {
      throw InputError(target.string(), "", "a folder that does not exist yet or is empty");
    }
  }
  // Everything is read and checked before the first byte is written.
  const std::vector<ArchiveEntry> entries = ReadArchive(archive, limits, warnings);

  const fs::path parent = target.has_parent_path() ? target.parent_path() : fs::path(".");
  fs::path temp;
  bool created = false;
  for (int attempt = 0; attempt < 16 && !created; ++attempt) {
    temp = parent / ("." + target.filename().string() + ".partial-" + RandomSuffix());
    created = fs::create_directory(temp, ec);
    if (ec) break;
  }
  if (!created) throw InputError(target.string(), "", "a writable parent folder: " + ec.message());

  std::vector<std::string> names;
  try {
    for (const ArchiveEntry& entry : entries) {
      // Names passed CheckName: relative, no "." / "..", no backslash or ':', so `dest` is below `temp`.
      const fs::path dest = temp / fs::path(entry.name);
      fs::create_directories(dest.parent_path());
      std::ofstream file(dest, std::ios::binary | std::ios::trunc);
      file.write(reinterpret_cast<const char*>(entry.data.data()), static_cast<std::streamsize>(entry.data.size()));
      file.close();
      if (!file) throw InputError(dest.string(), "", "a file that can be written");
      names.push_back(entry.name);
    }
    fs::rename(temp, target);
  } catch (const InputError&) {
    fs::remove_all(temp, ec);
    throw;
  } catch (const std::exception& e) {
    fs::remove_all(temp, ec);
    throw InputError(target.string(), "", std::string("a folder that can be written: ") + e.what());
  }
  return names;
}

}  // namespace u3mscan
