// The .u3ma reader: real archives from other tools, tolerated habits, and hostile archives that
// must fail with an InputError naming the archive, the entry and what was expected.

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

#include "core/error.h"
#include "tests/u3m_package/test_util.h"
#include "tests/u3m_package/zip_builder.h"
#include "u3m/texture_map.h"
#include "u3m/u3ma_archive.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;
using testing::Build;
using testing::BuildEntries;
using testing::Bytes;
using testing::RawArchive;
using testing::RawEntry;
using testing::ToBytes;

const fs::path kSample = fs::path(U3MSCAN_SHARED_DIR) / "reference/u3m/samples/browzwear-1.1-polartec-fleece.u3ma";

void WriteBytes(const fs::path& path, const Bytes& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

RawEntry Entry(const std::string& name, const std::string& content, std::uint16_t method = 8) {
  RawEntry e;
  e.name = name;
  e.content = ToBytes(content);
  e.method = method;
  return e;
}

// Writes the archive to disk, reads and extracts it; both must fail with an InputError that names
// the archive and contains `field_part` in its field and `expected_part` in its text, and the
// extraction must leave nothing behind.
void ExpectRefused(const Bytes& bytes, const std::string& field_part, const std::string& expected_part,
                   const ArchiveLimits& limits = {}) {
  TempDir dir;
  const fs::path archive = dir.path() / "hostile.u3ma";
  WriteBytes(archive, bytes);
  try {
    ReadArchive(archive, limits);
    ADD_FAILURE() << "accepted an archive that should fail with " << expected_part;
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), archive.string());
    EXPECT_NE(e.field().find(field_part), std::string::npos) << "field: " << e.field() << "\n" << e.what();
    EXPECT_NE(e.expected().find(expected_part), std::string::npos) << e.what();
  }
  const fs::path out = dir.path() / "out";
  EXPECT_THROW(ExtractArchive(archive, out, limits), InputError);
  EXPECT_FALSE(fs::exists(out));
  EXPECT_EQ(std::distance(fs::directory_iterator(dir.path()), fs::directory_iterator()), 1)
      << "only the archive itself: no partial output, nothing outside the output folder";
}

TEST(ArchiveRead, BrowzwearSample) {
  if (!fs::exists(kSample)) GTEST_SKIP() << "reference archive not present: " << kSample;
  std::vector<std::string> warnings;
  const auto entries = ReadArchive(kSample, {}, &warnings);
  ASSERT_EQ(entries.size(), 8u) << "9 entries minus the folder entry textures/";
  EXPECT_EQ(entries[0].name, "Polartec_Fleece,_100%_Polyester,_264_g_m2.u3m");
  EXPECT_EQ(entries[0].data.size(), 12814u);
  EXPECT_EQ(entries[0].data.front(), '{');
  EXPECT_EQ(entries[1].name, "physics.json");
  EXPECT_EQ(entries[7].name, "textures/polartec fleece, 100% polyester, 264 gm2_rough_.jpg");
  EXPECT_EQ(entries[7].data.size(), 489611u);
  // Browzwear writes version-made-by 2.0 and the deflate level bit: reported, not refused.
  bool made_by_warned = false;
  for (const auto& w : warnings) made_by_warned |= w.find("version-made-by") != std::string::npos;
  EXPECT_TRUE(made_by_warned);
}

TEST(ArchiveRead, BrowzwearSampleExtracts) {
  if (!fs::exists(kSample)) GTEST_SKIP() << "reference archive not present: " << kSample;
  TempDir dir;
  std::vector<std::string> warnings;
  const auto names = ExtractArchive(kSample, dir.path() / "fleece", {}, &warnings);
  EXPECT_EQ(names.size(), 8u);
  const fs::path normal = dir.path() / "fleece/textures/polartec fleece, 100% polyester, 264 gm2_nrm_.jpg";
  EXPECT_EQ(fs::file_size(normal), 2636758u);
  // Another vendor's texture reads through the same map reader: a normal map points out of the
  // surface on average.
  TextureFileInfo info;
  const Image map = ReadTextureMap(normal, MapKind::kNormal, &info);
  EXPECT_GT(info.geometry.width_px, 0);
  EXPECT_GT(map.ChannelMean(2), 0.5);
}

TEST(ArchiveRead, ToleratesExtraFieldsDescriptorsUnixAttributesAndCp437) {
  RawEntry with_extra = Entry("a.txt", "hello hello hello hello");
  with_extra.local_extra = testing::TimestampExtra();
  with_extra.central_extra = testing::TimestampExtra();
  RawEntry with_descriptor = Entry("b.txt", "descriptor descriptor descriptor");
  with_descriptor.descriptor = true;
  RawEntry unsigned_descriptor = Entry("c.txt", "no signature", 0);
  unsigned_descriptor.descriptor = true;
  unsigned_descriptor.descriptor_signature = false;
  RawEntry unix_file = Entry("d.txt", "unix");
  unix_file.made_by = 0x031E;
  unix_file.external = 0100644u << 16;
  RawEntry folder = Entry("textures/", "", 0);
  folder.external = 0x10;
  RawEntry cp437 = Entry(std::string("textures/caf\x82.png"), "cp437");  // 0x82 = e acute in CP437
  cp437.flags = 0;
  std::vector<std::string> warnings;
  const auto entries = ParseArchive(
      Build({{with_extra, with_descriptor, unsigned_descriptor, unix_file, folder, cp437}, {}, {}, "comment"}),
      "tolerant.u3ma", {}, &warnings);
  ASSERT_EQ(entries.size(), 5u);
  EXPECT_EQ(entries[0].data, ToBytes("hello hello hello hello"));
  EXPECT_EQ(entries[1].data, ToBytes("descriptor descriptor descriptor"));
  EXPECT_EQ(entries[2].data, ToBytes("no signature"));
  EXPECT_EQ(entries[4].name, "textures/caf\xc3\xa9.png");
  std::string all;
  for (const auto& w : warnings) all += w + "\n";
  for (const char* part : {"extra fields", "data descriptors", "version-made-by", "external attributes",
                           "code page 437", "archive comment"}) {
    EXPECT_NE(all.find(part), std::string::npos) << part << " not reported in:\n" << all;
  }
}

// Entry names follow the same path rule as a U3M's texture paths (u3m/relative_path.h): names that
// break only the 1.1 pattern are read with a warning, over-long names are refused.
TEST(ArchiveRead, NamesBreakingOnlyThePatternAreReadWithAWarning) {
  std::vector<std::string> warnings;
  const auto entries = ParseArchive(BuildEntries({Entry("textures/con.png", "x"), Entry("f%/a.png", "y")}),
                                    "pattern.u3ma", {}, &warnings);
  ASSERT_EQ(entries.size(), 2u);
  std::string all;
  for (const auto& w : warnings) all += w + "\n";
  EXPECT_NE(all.find("reserved device name"), std::string::npos) << all;
  EXPECT_NE(all.find("relative_file_path pattern"), std::string::npos) << all;
  ExpectRefused(BuildEntries({Entry(std::string(kMaxRelativePathBytes + 1, 'a'), "x")}), "entry",
                "at most " + std::to_string(kMaxRelativePathBytes) + " bytes");
}

TEST(ArchiveRead, RefusesEscapingNames) {
  ExpectRefused(BuildEntries({Entry("../evil.txt", "x")}), "../evil.txt", "'..'");
  ExpectRefused(BuildEntries({Entry("textures/../../evil.txt", "x")}), "evil", "'..'");
  ExpectRefused(BuildEntries({Entry("/etc/passwd", "x")}), "/etc/passwd", "absolute");
  ExpectRefused(BuildEntries({Entry("..\\evil.txt", "x")}), "evil", "backslash");
  ExpectRefused(BuildEntries({Entry("C:/evil.txt", "x")}), "evil", "drive letter");
  ExpectRefused(BuildEntries({Entry(std::string("a\0b", 3), "x")}), "entry", "NUL");
  ExpectRefused(BuildEntries({Entry("", "x")}), "entry #1", "non-empty");
}

TEST(ArchiveRead, RefusesDuplicatesAndFileFolderClashes) {
  ExpectRefused(BuildEntries({Entry("a.png", "1"), Entry("a.png", "2")}), "a.png", "unique");
  ExpectRefused(BuildEntries({Entry("a", "1"), Entry("a/b.png", "2")}), "\"a\"", "both a file and a folder");
}

TEST(ArchiveRead, RefusesSymlinksAndOtherSpecialFiles) {
  RawEntry link = Entry("textures/basecolor.png", "/etc/passwd", 0);
  link.made_by = 0x031E;
  link.external = 0120777u << 16;
  ExpectRefused(BuildEntries({link}), "basecolor.png", "symbolic link");
  RawEntry fifo = Entry("fifo", "", 0);
  fifo.made_by = 0x031E;
  fifo.external = 0010644u << 16;
  ExpectRefused(BuildEntries({fifo}), "fifo", "regular file");
  RawEntry reparse = Entry("junction", "x", 0);
  reparse.made_by = 0x0A3F;  // NTFS
  reparse.external = 0x400;
  ExpectRefused(BuildEntries({reparse}), "junction", "reparse point");
}

TEST(ArchiveRead, RefusesEncryptionAndUnsupportedMethods) {
  RawEntry encrypted = Entry("secret.png", "xxxxxxxxxxxx", 0);
  encrypted.flags |= 1;
  ExpectRefused(BuildEntries({encrypted}), "secret.png", "unencrypted");
  RawEntry aes = Entry("aes.png", "xxxxxxxxxxxx", 99);
  ExpectRefused(BuildEntries({aes}), "aes.png", "unencrypted");
  RawEntry bzip2 = Entry("b.png", "xxxxxxxxxxxx", 12);
  ExpectRefused(BuildEntries({bzip2}), "b.png", "method 0 (store) or 8 (deflate), got 12");
}

TEST(ArchiveRead, RefusesSizesAndChecksumsThatDoNotAddUp) {
  RawEntry bad_crc = Entry("a.txt", "checksum me");
  bad_crc.crc = 0xDEADBEEF;
  ExpectRefused(BuildEntries({bad_crc}), "a.txt", "CRC-32");

  RawEntry stored_lie = Entry("a.txt", "stored data", 0);
  stored_lie.uncompressed = 5;
  ExpectRefused(BuildEntries({stored_lie}), "a.txt", "equal sizes");

  RawEntry too_small = Entry("a.txt", std::string(1000, 'x') + "tail");
  too_small.uncompressed = 10;  // the stream goes on past the declared size
  ExpectRefused(BuildEntries({too_small}), "a.txt", "no more than the declared 10");

  RawEntry too_large = Entry("a.txt", "short");
  too_large.uncompressed = 500;
  ExpectRefused(BuildEntries({too_large}), "a.txt", "the declared 500");

  RawEntry compressed_lie = Entry("a.txt", "abcabcabcabcabcabcabc");
  compressed_lie.compressed = 3;  // the local header says the same, so the data runs into the next bytes
  ExpectRefused(BuildEntries({compressed_lie, Entry("b.txt", "b")}), "b.txt", "unclaimed bytes");
  ExpectRefused(BuildEntries({compressed_lie}), "central directory", "right after the last entry");

  RawEntry name_mismatch = Entry("textures/a.png", "x");
  name_mismatch.local_name = "../../a.png";
  ExpectRefused(BuildEntries({name_mismatch}), "textures/a.png", "same name in the local header");
}

TEST(ArchiveRead, RefusesTruncatedPaddedAndZip64Archives) {
  const Bytes good = BuildEntries({Entry("a.txt", std::string(2000, 'a') + "end"), Entry("b.txt", "b")});
  ExpectRefused(Bytes(good.begin(), good.begin() + static_cast<long>(good.size() / 2)), "end record", "truncated");
  ExpectRefused(Bytes(good.begin(), good.end() - 1), "end record", "");
  ExpectRefused(Bytes(good.begin(), good.begin() + 10), "end record", "at least 22 bytes");

  RawArchive trailing{{Entry("a.txt", "a")}, {}, ToBytes("garbage"), ""};
  ExpectRefused(Build(trailing), "end record", "nothing after the end record");
  RawArchive prefixed{{Entry("a.txt", "a")}, ToBytes("MZ-prefix"), {}, ""};
  ExpectRefused(Build(prefixed), "a.txt", "unclaimed bytes");
  RawEntry gap = Entry("b.txt", "b");
  gap.gap_before = 7;
  ExpectRefused(BuildEntries({Entry("a.txt", "a"), gap}), "b.txt", "7 unclaimed bytes");

  RawEntry zip64 = Entry("big.bin", "x", 0);
  zip64.compressed = 0xFFFFFFFF;
  zip64.uncompressed = 0xFFFFFFFF;
  ExpectRefused(BuildEntries({zip64}), "big.bin", "zip64");
}

TEST(ArchiveRead, RefusesOverlappingEntries) {
  // Entry b's local header sits inside entry a's stored data: two names for the same bytes.
  const Bytes inner = BuildEntries({Entry("b.txt", "hidden", 0)});
  const std::size_t inner_local = 30 + 5 + 6;  // local header of b.txt plus its data
  RawEntry a;
  a.name = "a.txt";
  a.method = 0;
  a.content = Bytes(inner.begin(), inner.begin() + static_cast<long>(inner_local));
  RawEntry b = Entry("b.txt", "hidden", 0);
  b.central_offset = 30 + 5;  // right after a's local header
  // Build() writes b's own copy too; the central directory points both at the embedded copy.
  RawArchive archive{{a, b}, {}, {}, ""};
  Bytes bytes = Build(archive);
  ExpectRefused(bytes, "b.txt", "does not overlap");
}

TEST(ArchiveRead, RefusesZipBombs) {
  // 16 MiB of zeros deflate to ~16 KiB: ratio ~1000:1 declared honestly.
  RawEntry bomb;
  bomb.name = "textures/bomb.png";
  bomb.content = Bytes(std::size_t{16} << 20, 0);
  const Bytes honest = BuildEntries({bomb});
  ArchiveLimits limits;
  limits.max_compression_ratio = 100.0;
  ExpectRefused(honest, "bomb.png", "compression ratio", limits);

  // The same stream with a modest declared size: inflating must stop at the declared size.
  RawEntry liar = bomb;
  liar.uncompressed = 4096;
  ExpectRefused(BuildEntries({liar}), "bomb.png", "no more than the declared 4096");

  ArchiveLimits small;
  small.max_entry_bytes = 1 << 20;
  ExpectRefused(honest, "bomb.png", "uncompressed bytes per entry", small);

  RawEntry part = Entry("a.bin", std::string(600 << 10, 'a'));
  RawEntry part2 = Entry("b.bin", std::string(600 << 10, 'b'));
  small.max_total_bytes = 1 << 20;
  small.max_compression_ratio = 1e9;  // runs of one letter deflate beyond 1000:1; test the total alone
  ExpectRefused(BuildEntries({part, part2}), "b.bin", "uncompressed bytes in all", small);

  ArchiveLimits few;
  few.max_entries = 2;
  ExpectRefused(BuildEntries({Entry("1", "1"), Entry("2", "2"), Entry("3", "3")}), "end record", "at most 2 entries", few);
}

TEST(ArchiveRead, NotAZipAtAll) {
  ExpectRefused(ToBytes(std::string(100, 'x')), "end record", "ZIP");
}

// Mutated archives (fixed seed): every one is either read or refused with an InputError; nothing
// else may escape (no crash, no other exception type, no read past the buffer under ASan).
TEST(ArchiveRead, RandomCorruptionIsReadOrRefusedNeverACrash) {
  RawEntry descriptor = Entry("textures/b.png", std::string(300, 'b') + "end");
  descriptor.descriptor = true;
  const Bytes good = BuildEntries({Entry("m.u3m", "{\"schema\": \"1.1\"}"), descriptor, Entry("c.bin", "ccc", 0)});
  constexpr int kMutants = 3000;
  std::mt19937 rng(7);
  int refused = 0;
  for (int i = 0; i < kMutants; ++i) {
    Bytes mutant = good;
    const int flips = 1 + static_cast<int>(rng() % 4);
    for (int f = 0; f < flips; ++f) mutant[rng() % mutant.size()] = static_cast<std::uint8_t>(rng());
    if (rng() % 8 == 0) mutant.resize(rng() % mutant.size());
    try {
      std::vector<std::string> warnings;
      ParseArchive(mutant, "mutant.u3ma", {}, &warnings);
    } catch (const InputError&) {
      ++refused;
    }
  }
  EXPECT_GT(refused, kMutants / 2) << "most corruptions must be caught (CRCs, sizes, signatures)";
}

TEST(ArchiveExtract, WritesBelowTheFolderAndRefusesNonEmptyTargets) {
  TempDir dir;
  const fs::path archive = dir.path() / "ok.u3ma";
  WriteArchive(archive, {{"m.u3m", {'{', '}'}}, {"textures/n.png", {1, 2, 3}}});
  const auto names = ExtractArchive(archive, dir.path() / "out");
  EXPECT_EQ(names, (std::vector<std::string>{"m.u3m", "textures/n.png"}));
  EXPECT_EQ(fs::file_size(dir.path() / "out/textures/n.png"), 3u);
  EXPECT_THROW(ExtractArchive(archive, dir.path() / "out"), InputError) << "target not empty";
  fs::create_directory(dir.path() / "empty");
  EXPECT_NO_THROW(ExtractArchive(archive, dir.path() / "empty"));
  EXPECT_TRUE(fs::exists(dir.path() / "empty/m.u3m"));
}

}  // namespace
}  // namespace u3mscan
