// The .u3ma writer: byte-exact to docs/u3m-conventions.md, readable by our reader and by other tools.

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>

#include "core/error.h"
#include "tests/u3m_package/test_util.h"
#include "tests/u3m_package/zip_builder.h"
#include "u3m/u3ma_archive.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;
using testing::Bytes;
using testing::Get16;
using testing::Get32;

constexpr std::time_t kFixedTimeUtc = 1709646330;  // 2024-03-05 13:45:30 UTC
constexpr std::uint16_t kFixedDosTime = (13 << 11) | (45 << 5) | (30 / 2);
constexpr std::uint16_t kFixedDosDate = ((2024 - 1980) << 9) | (3 << 5) | 5;

std::vector<ArchiveEntry> SampleEntries() {
  std::mt19937 rng(42);
  Bytes noise(5000);
  for (auto& b : noise) b = static_cast<std::uint8_t>(rng());
  const std::string json = R"({"schema": "1.1", "material": {"name": "Fleece ü"}, "custom": null})";
  Bytes repetitive;
  for (int i = 0; i < 400; ++i) repetitive.insert(repetitive.end(), json.begin(), json.end());
  return {
      {"Fleece ü.u3m", Bytes(json.begin(), json.end())},
      {"textures/basecolor.png", noise},       // incompressible: must be stored
      {"textures/roughness.tif", repetitive},  // compressible: must be deflated
      {"empty.txt", {}},
  };
}

ArchiveWriteOptions FixedOptions() {
  ArchiveWriteOptions options;
  options.modified_utc = kFixedTimeUtc;
  return options;
}

// Walks the archive byte by byte with the builder's independent accessors and checks every field
// the conventions fix.
TEST(ArchiveWrite, EveryHeaderFieldFollowsTheConventions) {
  const auto entries = SampleEntries();
  const Bytes bytes = SerializeArchive(entries, "test.u3ma", FixedOptions());

  std::size_t pos = 0;
  std::vector<std::uint32_t> local_offsets;
  std::vector<std::uint16_t> methods;
  for (const ArchiveEntry& entry : entries) {
    SCOPED_TRACE(entry.name);
    local_offsets.push_back(static_cast<std::uint32_t>(pos));
    ASSERT_EQ(Get32(bytes, pos), 0x04034b50u);
    EXPECT_EQ(Get16(bytes, pos + 4), 0x0014);              // version needed 2.0
    EXPECT_EQ(Get16(bytes, pos + 6), 0x0800);              // only the UTF-8 flag: no descriptor, no encryption
    const std::uint16_t method = Get16(bytes, pos + 8);
    EXPECT_TRUE(method == 0 || method == 8);
    methods.push_back(method);
    EXPECT_EQ(Get16(bytes, pos + 10), kFixedDosTime);
    EXPECT_EQ(Get16(bytes, pos + 12), kFixedDosDate);
    EXPECT_EQ(Get32(bytes, pos + 14), testing::Crc(entry.data));
    const std::uint32_t csize = Get32(bytes, pos + 18);
    EXPECT_EQ(Get32(bytes, pos + 22), entry.data.size());  // sizes in the local header
    if (method == 0) {
      EXPECT_EQ(csize, entry.data.size());
    }
    EXPECT_EQ(Get16(bytes, pos + 26), entry.name.size());
    EXPECT_EQ(Get16(bytes, pos + 28), 0);                  // no extra field
    EXPECT_EQ(std::string(bytes.begin() + pos + 30, bytes.begin() + pos + 30 + entry.name.size()), entry.name);
    pos += 30 + entry.name.size() + csize;                 // no data descriptor follows
  }
  EXPECT_EQ(methods[1], 0) << "incompressible data is stored";
  EXPECT_EQ(methods[2], 8) << "compressible data is deflated";
  EXPECT_EQ(methods[3], 0) << "an empty entry is stored";

  const std::size_t cd_offset = pos;
  for (std::size_t i = 0; i < entries.size(); ++i) {
    SCOPED_TRACE(entries[i].name);
    ASSERT_EQ(Get32(bytes, pos), 0x02014b50u);
    EXPECT_EQ(Get16(bytes, pos + 4), 0x003F);  // version made by
    EXPECT_EQ(Get16(bytes, pos + 6), 0x0014);
    EXPECT_EQ(Get16(bytes, pos + 8), 0x0800);
    EXPECT_EQ(Get16(bytes, pos + 10), methods[i]);
    EXPECT_EQ(Get16(bytes, pos + 12), kFixedDosTime);
    EXPECT_EQ(Get16(bytes, pos + 14), kFixedDosDate);
    EXPECT_EQ(Get32(bytes, pos + 16), testing::Crc(entries[i].data));
    EXPECT_EQ(Get32(bytes, pos + 24), entries[i].data.size());
    EXPECT_EQ(Get16(bytes, pos + 28), entries[i].name.size());
    EXPECT_EQ(Get16(bytes, pos + 30), 0);  // extra
    EXPECT_EQ(Get16(bytes, pos + 32), 0);  // comment
    EXPECT_EQ(Get16(bytes, pos + 34), 0);  // disk
    EXPECT_EQ(Get16(bytes, pos + 36), 0);  // internal attributes
    EXPECT_EQ(Get32(bytes, pos + 38), 0u); // external attributes
    EXPECT_EQ(Get32(bytes, pos + 42), local_offsets[i]);
    pos += 46 + entries[i].name.size();
  }
  const std::size_t cd_size = pos - cd_offset;
  ASSERT_EQ(Get32(bytes, pos), 0x06054b50u);
  EXPECT_EQ(Get16(bytes, pos + 4), 0);
  EXPECT_EQ(Get16(bytes, pos + 6), 0);
  EXPECT_EQ(Get16(bytes, pos + 8), entries.size());
  EXPECT_EQ(Get16(bytes, pos + 10), entries.size());
  EXPECT_EQ(Get32(bytes, pos + 12), cd_size);
  EXPECT_EQ(Get32(bytes, pos + 16), cd_offset);
  EXPECT_EQ(Get16(bytes, pos + 20), 0);     // no comment
  EXPECT_EQ(pos + 22, bytes.size());        // nothing after the end record
  EXPECT_EQ(local_offsets.front(), 0u);     // nothing before the first entry
}

TEST(ArchiveWrite, RoundTripKeepsNamesBytesAndOrder) {
  TempDir dir;
  const auto entries = SampleEntries();
  for (ArchiveCompression compression : {ArchiveCompression::kStore, ArchiveCompression::kDeflate}) {
    ArchiveWriteOptions options = FixedOptions();
    options.compression = compression;
    const fs::path path = dir.path() / "round.u3ma";
    WriteArchive(path, entries, options);
    std::vector<std::string> warnings;
    const auto read = ReadArchive(path, {}, &warnings);
    EXPECT_TRUE(warnings.empty()) << warnings.front();
    ASSERT_EQ(read.size(), entries.size());
    for (std::size_t i = 0; i < entries.size(); ++i) {
      EXPECT_EQ(read[i].name, entries[i].name);
      EXPECT_EQ(read[i].data, entries[i].data) << entries[i].name;
    }
  }
}

TEST(ArchiveWrite, SameInputAndTimeGiveIdenticalBytes) {
  EXPECT_EQ(SerializeArchive(SampleEntries(), "a", FixedOptions()), SerializeArchive(SampleEntries(), "b", FixedOptions()));
}

TEST(ArchiveWrite, TimesAreUtcWhateverTheLocalZone) {
  const char* old = std::getenv("TZ");
  const std::string saved = old ? old : "";
  setenv("TZ", "Pacific/Kiritimati", 1);  // UTC+14: a local-time writer would shift the date
  tzset();
  const Bytes bytes = SerializeArchive({{"a.txt", {1, 2, 3}}}, "a", FixedOptions());
  if (old) setenv("TZ", saved.c_str(), 1); else unsetenv("TZ");
  tzset();
  EXPECT_EQ(Get16(bytes, 10), kFixedDosTime);
  EXPECT_EQ(Get16(bytes, 12), kFixedDosDate);
}

TEST(ArchiveWrite, HighRatioDataIsStoredSoOurReaderAcceptsIt) {
  // 4 MiB of zeros deflate at about 1030:1, above the reader's default ratio limit.
  const std::vector<ArchiveEntry> entries = {{"zeros.bin", Bytes(std::size_t{4} << 20, 0)}};
  const Bytes bytes = SerializeArchive(entries, "zeros.u3ma", FixedOptions());
  EXPECT_EQ(Get16(bytes, 8), 0) << "stored";
  EXPECT_EQ(ParseArchive(bytes, "zeros.u3ma").at(0).data.size(), entries[0].data.size());
}

TEST(ArchiveWrite, LargeEntriesAreDeflatedOnlyWhenATrialPays) {
  std::mt19937 rng(3);
  Bytes noise(std::size_t{1} << 20);  // like a PNG: compressed already
  for (auto& b : noise) b = static_cast<std::uint8_t>(rng());
  Bytes text;
  while (text.size() < noise.size()) text.push_back(static_cast<std::uint8_t>("{\"r\": 0.5, \"g\": 0.25}\n"[rng() % 22]));
  const Bytes bytes = SerializeArchive({{"noise.png", noise}, {"text.u3m", text}}, "large.u3ma", FixedOptions());
  EXPECT_EQ(Get16(bytes, 8), 0) << "incompressible: stored";
  const std::size_t second = 30 + 9 + noise.size();
  EXPECT_EQ(Get16(bytes, second + 8), 8) << "compressible: deflated";
  const auto read = ParseArchive(bytes, "large.u3ma");
  EXPECT_EQ(read.at(0).data, noise);
  EXPECT_EQ(read.at(1).data, text);
}

TEST(ArchiveWrite, BadNamesAreRefusedAndNothingIsWritten) {
  TempDir dir;
  const fs::path path = dir.path() / "bad.u3ma";
  const std::vector<std::string> bad = {"../up.png", "/abs.png", "a\\b.png", "C:/x.png", "a//b.png", "./a.png",
                                        "a/./b.png", "trailing.", "dir /x.png", "", "x/", "ctl\x01.png",
                                        std::string("bad\xff.png"),
                                        // the 1.1 pattern and the length limit, as for a U3M's paths
                                        "textures/CON.png", "f%/a.png", "a|b.png",
                                        std::string(kMaxRelativePathBytes + 1, 'a')};
  for (const std::string& name : bad) {
    SCOPED_TRACE(name);
    try {
      WriteArchive(path, {{"ok.u3m", {1}}, {name, {2}}});
      ADD_FAILURE() << "accepted";
    } catch (const InputError& e) {
      EXPECT_EQ(e.file(), path.string());
      EXPECT_NE(e.field().find("entry"), std::string::npos) << e.what();
    }
    EXPECT_TRUE(fs::is_empty(dir.path())) << "no file, no temporary left behind";
  }
  for (const auto& duplicate : std::vector<std::vector<ArchiveEntry>>{
           {{"a.png", {1}}, {"a.png", {2}}}, {{"a.png", {1}}, {"A.PNG", {2}}}, {{"a", {1}}, {"a/b", {2}}}}) {
    EXPECT_THROW(WriteArchive(path, duplicate), InputError);
    EXPECT_TRUE(fs::is_empty(dir.path()));
  }
}

TEST(ArchiveWrite, ReplacesAnExistingFileWholeAndLeavesNoTemporary) {
  TempDir dir;
  const fs::path path = dir.path() / "out.u3ma";
  WriteArchive(path, {{"one.txt", {1}}}, FixedOptions());
  WriteArchive(path, {{"two.txt", {2, 2}}}, FixedOptions());
  const auto read = ReadArchive(path);
  ASSERT_EQ(read.size(), 1u);
  EXPECT_EQ(read[0].name, "two.txt");
  EXPECT_EQ(std::distance(fs::directory_iterator(dir.path()), fs::directory_iterator()), 1);
}

// Other tools must read what we write: Python's zipfile (always on the Debian image) and Info-ZIP's
// unzip/zipinfo when installed.
TEST(ArchiveWrite, PythonZipfileAndInfoZipAcceptOurArchives) {
  TempDir dir;
  const fs::path path = dir.path() / "tools.u3ma";
  WriteArchive(path, SampleEntries(), FixedOptions());
  const fs::path script = dir.path() / "check.py";
  {
    std::ofstream py(script);
    py << "import sys, zipfile\n"
          "z = zipfile.ZipFile(sys.argv[1])\n"
          "assert z.testzip() is None\n"
          "for i in z.infolist():\n"
          "    assert i.flag_bits == 0x800, hex(i.flag_bits)\n"
          "    assert i.create_version == 63 and i.create_system == 0 and i.extract_version == 20\n"
          "    assert i.external_attr == 0 and i.extra == b'' and i.comment == b''\n"
          "    assert i.date_time == (2024, 3, 5, 13, 45, 30), i.date_time\n"
          "assert [i.filename for i in z.infolist()] == "
          "['Fleece \\u00fc.u3m', 'textures/basecolor.png', 'textures/roughness.tif', 'empty.txt']\n"
          "assert z.read('empty.txt') == b''\n"
          "print('ok')\n";
  }
  const std::string python = kSystemPython;
  if (!fs::exists(python)) GTEST_SKIP() << "no " << python << " to cross-check the archive";
  EXPECT_EQ(RunCommand(python + " " + Quote(script) + " " + Quote(path)), 0);
  if (RunCommand("command -v unzip >/dev/null 2>&1") == 0) {
    EXPECT_EQ(RunCommand("unzip -tqq " + Quote(path)), 0) << "unzip -t";
  } else {
    std::cout << "[ INFO     ] unzip not installed: Info-ZIP cross-check skipped\n";
  }
  if (RunCommand("command -v zipinfo >/dev/null 2>&1") == 0) {
    EXPECT_EQ(RunCommand("zipinfo -v " + Quote(path) + " >/dev/null"), 0) << "zipinfo -v";
  }
}

TEST(RelativePath, AcceptsPlainRelativeNamesAndExplainsTheRest) {
  EXPECT_EQ(RelativePathProblem("textures/basecolor.png"), "");
  EXPECT_EQ(RelativePathProblem("textures/polartec fleece, 100% polyester_base_.jpg"), "");
  EXPECT_NE(RelativePathProblem("../x.png").find(".."), std::string::npos);
  EXPECT_NE(RelativePathProblem("/x.png").find("absolute"), std::string::npos);
  EXPECT_NE(RelativePathProblem("x\\y.png").find("backslash"), std::string::npos);
  EXPECT_NE(RelativePathProblem("D:x.png").find("drive"), std::string::npos);
  EXPECT_NE(RelativePathProblem("x.png ").find("' '"), std::string::npos);
}

}  // namespace
}  // namespace u3mscan
