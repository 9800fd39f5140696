#pragma once
// A raw ZIP builder for tests: every header field can be set by hand, so the tests can build the
// hostile and the merely unusual archives the reader must refuse or tolerate. Independent of the
// writer under test (it shares no code with u3m/u3ma_archive.cc).

#include <zlib.h>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace u3mscan::testing {

using Bytes = std::vector<std::uint8_t>;

inline void Put16(Bytes& b, std::uint32_t v) {
  b.push_back(static_cast<std::uint8_t>(v & 0xFF));
  b.push_back(static_cast<std::uint8_t>((v >> 8) & 0xFF));
}
inline void Put32(Bytes& b, std::uint32_t v) {
  Put16(b, v & 0xFFFF);
  Put16(b, v >> 16);
}
inline std::uint16_t Get16(const Bytes& b, std::size_t p) { return static_cast<std::uint16_t>(b[p] | (b[p + 1] << 8)); }
inline std::uint32_t Get32(const Bytes& b, std::size_t p) {
  return static_cast<std::uint32_t>(Get16(b, p)) | (static_cast<std::uint32_t>(Get16(b, p + 2)) << 16);
}

inline Bytes ToBytes(const std::string& s) { return Bytes(s.begin(), s.end()); }

inline std::uint32_t Crc(const Bytes& data) {
  return static_cast<std::uint32_t>(crc32(crc32(0, nullptr, 0), data.data(), static_cast<uInt>(data.size())));
}

inline Bytes RawDeflate(const Bytes& data, int level = 9) {
  z_stream zs{};
  deflateInit2(&zs, level, Z_DEFLATED, -15, 9, Z_DEFAULT_STRATEGY);
  Bytes out(deflateBound(&zs, static_cast<uLong>(data.size())));
  zs.next_in = const_cast<Bytef*>(data.data());
  zs.avail_in = static_cast<uInt>(data.size());
  zs.next_out = out.data();
  zs.avail_out = static_cast<uInt>(out.size());
  deflate(&zs, Z_FINISH);
  out.resize(zs.total_out);
  deflateEnd(&zs);
  return out;
}

struct RawEntry {
  std::string name;
  Bytes content;                     // uncompressed content
  std::uint16_t method = 8;          // 0 store, 8 deflate (anything else is written as stored bytes)
  std::uint16_t flags = 0x0800;
  std::uint16_t made_by = 0x003F;
  std::uint16_t needed = 0x0014;
  std::uint32_t external = 0;
  std::uint16_t dos_time = 0x6DAF;   // 13:45:30
  std::uint16_t dos_date = 0x5865;   // 2024-03-05
  Bytes local_extra, central_extra;
  bool descriptor = false;           // bit 3: zeros in the local header, descriptor after the data
  bool descriptor_signature = true;
  // Overrides of what the builder would compute.
  std::optional<Bytes> payload;      // the stored bytes (default: content, deflated for method 8)
  std::optional<std::uint32_t> crc, compressed, uncompressed;
  std::optional<std::string> local_name;
  std::optional<std::uint32_t> central_offset;  // local header offset as the central directory says
  std::size_t gap_before = 0;        // junk bytes before this entry's local header
};

struct RawArchive {
  std::vector<RawEntry> entries;
  Bytes prefix, trailer;
  std::string comment;
};

inline Bytes Build(const RawArchive& archive) {
  Bytes out = archive.prefix;
  Bytes central;
  for (const RawEntry& e : archive.entries) {
    out.insert(out.end(), e.gap_before, 0x5A);
    const Bytes payload = e.payload ? *e.payload : (e.method == 8 ? RawDeflate(e.content) : e.content);
    const std::uint32_t crc = e.crc.value_or(Crc(e.content));
    const std::uint32_t csize = e.compressed.value_or(static_cast<std::uint32_t>(payload.size()));
    const std::uint32_t usize = e.uncompressed.value_or(static_cast<std::uint32_t>(e.content.size()));
    const std::uint32_t offset = e.central_offset.value_or(static_cast<std::uint32_t>(out.size()));
    const std::string local_name = e.local_name.value_or(e.name);
    Put32(out, 0x04034b50);
    Put16(out, e.needed);
    Put16(out, e.flags | (e.descriptor ? 0x0008 : 0));
    Put16(out, e.method);
    Put16(out, e.dos_time);
    Put16(out, e.dos_date);
    Put32(out, e.descriptor ? 0 : crc);
    Put32(out, e.descriptor ? 0 : csize);
    Put32(out, e.descriptor ? 0 : usize);
    Put16(out, static_cast<std::uint32_t>(local_name.size()));
    Put16(out, static_cast<std::uint32_t>(e.local_extra.size()));
    out.insert(out.end(), local_name.begin(), local_name.end());
    out.insert(out.end(), e.local_extra.begin(), e.local_extra.end());
    out.insert(out.end(), payload.begin(), payload.end());
    if (e.descriptor) {
      if (e.descriptor_signature) Put32(out, 0x08074b50);
      Put32(out, crc);
      Put32(out, csize);
      Put32(out, usize);
    }
    Put32(central, 0x02014b50);
    Put16(central, e.made_by);
    Put16(central, e.needed);
    Put16(central, e.flags | (e.descriptor ? 0x0008 : 0));
    Put16(central, e.method);
    Put16(central, e.dos_time);
    Put16(central, e.dos_date);
    Put32(central, crc);
    Put32(central, csize);
    Put32(central, usize);
    Put16(central, static_cast<std::uint32_t>(e.name.size()));
    Put16(central, static_cast<std::uint32_t>(e.central_extra.size()));
    Put16(central, 0);
    Put16(central, 0);
    Put16(central, 0);
    Put32(central, e.external);
    Put32(central, offset);
    central.insert(central.end(), e.name.begin(), e.name.end());
    central.insert(central.end(), e.central_extra.begin(), e.central_extra.end());
  }
  const std::uint32_t cd_offset = static_cast<std::uint32_t>(out.size());
  out.insert(out.end(), central.begin(), central.end());
  Put32(out, 0x06054b50);
  Put16(out, 0);
  Put16(out, 0);
  Put16(out, static_cast<std::uint32_t>(archive.entries.size()));
  Put16(out, static_cast<std::uint32_t>(archive.entries.size()));
  Put32(out, static_cast<std::uint32_t>(central.size()));
  Put32(out, cd_offset);
  Put16(out, static_cast<std::uint32_t>(archive.comment.size()));
  out.insert(out.end(), archive.comment.begin(), archive.comment.end());
  out.insert(out.end(), archive.trailer.begin(), archive.trailer.end());
  return out;
}

inline Bytes BuildEntries(std::vector<RawEntry> entries) {
  RawArchive archive;
  archive.entries = std::move(entries);
  return Build(archive);
}

// An extended-timestamp extra field (0x5455) as Info-ZIP writes it.
inline Bytes TimestampExtra() {
  Bytes b;
  Put16(b, 0x5455);
  Put16(b, 5);
  b.push_back(1);
  Put32(b, 1709646330);
  return b;
}

}  // namespace u3mscan::testing
