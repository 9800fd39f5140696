// Hostile input through the built `u3mscan` executable (docs/hostile-input.md): every bad file of
// the checked-in corpus (tests/hostile/{u3m,u3ma,manifest,images}, written by make_corpus.py) and
// the large ones made here (deep nesting, a zip bomb, a truncated DNG) must give a message that
// names the file and the field, end with the documented exit code (2: unreadable input) by itself
// (no signal, no abort, no sanitizer report), and leave nothing in the output folder or the
// temporary folder. Each case also has a control that succeeds, so a refusal is not an accident of
// the set-up.

#include <gtest/gtest.h>

#include <sys/stat.h>

#include <string>
#include <vector>

#include "capture/dng_writer.h"
#include "core/image.h"
#include "hostile_util.h"
#include "u3m/image_io.h"

namespace u3mscan::hostile {
namespace {

// Exit codes documented in cli/command.h and `u3mscan validate --help`.
constexpr int kExitOk = 0;
constexpr int kExitInvalid = 1;
constexpr int kExitUnreadable = 2;
constexpr int kExitCaptureFailed = 1;  // `process`: some capture failed (bad usage is 2)

constexpr int kFrameSide = 32;         // the cameras of manifest/valid.json
constexpr int kNestingDepth = 100000;  // far deeper than any recursive parser's stack allows
// A 2 MB capture.json: a recursive copy of it needs ~100 MB of stack (the default is 8 MB).
constexpr int kManifestNestingDepth = 1000000;

// One bad input and what its message must name besides the file.
struct Case {
  std::string file;     // below tests/hostile/<folder>/, or a generated name
  std::string mention;  // the JSON pointer or entry name the message must contain
};
std::ostream& operator<<(std::ostream& os, const Case& c) { return os << c.file; }
// A test name from a case's file name ("truncated.u3m" -> "truncated_u3m").
std::string FileTestName(std::string name) {
  for (char& c : name)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  return name;
}
std::string CaseName(const ::testing::TestParamInfo<Case>& info) { return FileTestName(info.param.file); }

std::string DeepArray(int depth) { return std::string(depth, '[') + std::string(depth, ']'); }

// ------------------------------------------------------------------------------- U3M files

const std::vector<Case>& BadU3mCases() {
  static const std::vector<Case> cases = {
      {"truncated.u3m", "valid JSON"},
      {"empty.u3m", "valid JSON"},
      {"binary_garbage.u3m", "valid JSON"},
      {"not_an_object.u3m", "a U3M object"},
      {"wrong_type_name.u3m", "/material/name"},
      {"wrong_type_constant.u3m", "/material/front/roughness/constant"},
      {"wrong_type_front.u3m", "/material/front"},
      {"nan_token.u3m", "/material/front/roughness/constant"},
      {"infinity_token.u3m", "/material/front/roughness/constant"},
      {"huge_number.u3m", "/material/front/roughness/constant"},
      {"big_number.u3m", "/material/front/roughness/constant"},
      {"duplicate_keys.u3m", "/material/name"},
      {"unknown_schema.u3m", "/schema"},
      {"bad_timestamp.u3m", "/material/created"},
      {"invalid_utf8.u3m", "/material/name"},
      {"traversal_texture.u3m", "/material/front/basecolor/texture/image/path"},
      {"absolute_texture.u3m", "/material/front/basecolor/texture/image/path"},
      {"drive_texture.u3m", "/material/front/basecolor/texture/image/path"},
      {"backslash_traversal_texture.u3m", "/material/front/basecolor/texture/image/path"},
      {"deep_nesting.u3m", "/custom"},  // generated: [[[...]]] kNestingDepth deep in a custom section
  };
  return cases;
}

// Copies (or makes) the case's file into `dir` and returns its path.
fs::path PlaceU3m(const std::string& file, const fs::path& dir) {
  const fs::path target = dir / file;
  if (file == "deep_nesting.u3m") {
    std::string text = ReadFile(CorpusDir() / "u3m" / "base_valid.u3m");
    const std::size_t brace = text.rfind('}');
    text = text.substr(0, brace) + ", \"custom\": {\"vendor\": " + DeepArray(kNestingDepth) + "}}";
    WriteFile(target, text);
  } else {
    fs::create_directories(dir);
    fs::copy_file(CorpusDir() / "u3m" / file, target);
  }
  return target;
}

TEST(HostileU3m, ControlIsValidAndConverts) {
  TempDir tmp;
  const fs::path in = PlaceU3m("base_valid.u3m", tmp.path() / "in");
  EXPECT_TRUE(CleanExit(RunU3mscan({"validate", in.string()}, tmp.path() / "t1"), kExitOk, {"valid"}));
  EXPECT_TRUE(CleanExit(RunU3mscan({"convert", in.string(), (tmp.path() / "out" / "x.u3ma").string()}, tmp.path() / "t2"),
                        kExitOk, {"wrote"}));
  EXPECT_TRUE(fs::exists(tmp.path() / "out" / "x.u3ma"));
}

// ------------------------------------------------------------------------------- textures of a U3M

// tests/hostile/images files placed as textures/basecolor.png of a valid material.
const std::vector<Case>& BadTextureCases() {
  static const std::vector<Case> cases = {
      {"truncated_after_header.png", "textures/basecolor.png"},
      {"corrupt_data.png", "textures/basecolor.png"},
      {"text.png", "textures/basecolor.png"},
      {"enormous_dimensions.png", "textures/basecolor.png"},  // 65536 x 65536 in a 100-byte file
      {"large_dimensions.png", "textures/basecolor.png"},     // 36000 x 36000: over the 2^30-sample cap
  };
  return cases;
}

class HostileTexture : public ::testing::TestWithParam<Case> {};

TEST_P(HostileTexture, ValidateAndConvertNameTheTexture) {
  TempDir tmp;
  const fs::path in = PlaceU3m("texture_base.u3m", tmp.path() / "in");
  fs::create_directories(tmp.path() / "in" / "textures");
  fs::copy_file(CorpusDir() / "images" / GetParam().file, tmp.path() / "in" / "textures" / "basecolor.png");
  const fs::path out = tmp.path() / "out";
  fs::create_directories(out);
  const std::vector<RunResult> runs = RunU3mscanAll({{{"validate", in.string()}, tmp.path() / "t1"},
                                                    {{"convert", in.string(), (out / "converted.u3ma").string()}, tmp.path() / "t2"}});
  EXPECT_TRUE(CleanExit(runs[0], kExitInvalid, {in.string() + ": INVALID", GetParam().mention})) << "validate";
  EXPECT_TRUE(CleanExit(runs[1], kExitUnreadable, {GetParam().mention})) << "convert";
  EXPECT_TRUE(NothingIn(out));
  EXPECT_TRUE(NothingIn(tmp.path() / "t2"));
}

INSTANTIATE_TEST_SUITE_P(Corpus, HostileTexture, ::testing::ValuesIn(BadTextureCases()), CaseName);

// ------------------------------------------------------------------------------- .u3ma packages

constexpr std::size_t kBombBytes = std::size_t{64} << 20;  // zeros deflate ~1030:1, above the 1000:1 guard
constexpr std::size_t kTooManyEntries = 5000;              // above ArchiveLimits::max_entries (4096)

const std::vector<Case>& BadU3maCases() {
  static const std::vector<Case> cases = {
      {"not_a_zip.u3ma", "end record"},
      {"empty.u3ma", "end record"},
      {"truncated.u3ma", "end record"},
      {"traversal_entry.u3ma", "../evil.png"},
      {"absolute_entry.u3ma", "/tmp/u3mscan_hostile_evil.png"},
      {"backslash_entry.u3ma", "..\\evil.png"},
      {"duplicate_entry.u3ma", "material.u3m"},
      {"symlink_entry.u3ma", "textures/link.png"},
      {"no_material.u3ma", ".u3m"},
      {"two_materials.u3ma", ".u3m"},
      {"bad_material.u3ma", "/material/front/roughness/constant"},
      {"traversal_texture.u3ma", "/material/front/basecolor/texture/image/path"},
      {"sizes_lie.u3ma", "material.u3m"},
      {"encrypted.u3ma", "material.u3m"},
      {"overlapping_entries.u3ma", "copy.u3m"},
      {"zip_bomb.u3ma", "textures/bomb.png"},  // generated
      {"too_many_entries.u3ma", "entries"},    // generated
  };
  return cases;
}

fs::path PlaceU3ma(const std::string& file, const fs::path& dir) {
  const fs::path target = dir / file;
  const std::string material = ReadFile(CorpusDir() / "u3m" / "base_valid.u3m");
  if (file == "zip_bomb.u3ma") {
    WriteFile(target, BuildZip({{"material.u3m", material, true}, {"textures/bomb.png", std::string(kBombBytes, '\0'), true}}));
  } else if (file == "too_many_entries.u3ma") {
    std::vector<ZipEntrySpec> entries{{"material.u3m", material, false}};
    for (std::size_t i = 0; i < kTooManyEntries; ++i) entries.push_back({"t/" + std::to_string(i), "x", false});
    WriteFile(target, BuildZip(entries));
  } else {
    fs::create_directories(dir);
    fs::copy_file(CorpusDir() / "u3ma" / file, target);
  }
  return target;
}

TEST(HostileU3ma, ControlBuiltHereIsValid) {
  TempDir tmp;
  const fs::path in = tmp.path() / "in" / "good.u3ma";
  WriteFile(in, BuildZip({{"material.u3m", ReadFile(CorpusDir() / "u3m" / "base_valid.u3m"), true}}));
  EXPECT_TRUE(CleanExit(RunU3mscan({"validate", in.string()}, tmp.path() / "t1"), kExitOk, {"valid"}));
}

// ------------------------------------------------------------------------------- both material corpora

// The .u3m and .u3ma corpora go through the same runs: one `validate` over every bad file, then
// `info` and `convert` per file. What differs between them is in this table.
struct MaterialCorpus {
  std::string name;  // the corpus folder below tests/hostile
  const std::vector<Case>& (*cases)();
  fs::path (*place)(const std::string& file, const fs::path& dir);
  // Files an entry unpacked outside the temporary folder would make: relative to the test's
  // temporary folder, or absolute (the hostile archives name these).
  std::vector<std::string> escapes;
};
std::ostream& operator<<(std::ostream& os, const MaterialCorpus& c) { return os << c.name; }

const std::vector<MaterialCorpus>& MaterialCorpora() {
  static const std::vector<MaterialCorpus> corpora = {
      {"u3m", BadU3mCases, PlaceU3m, {}},
      {"u3ma", BadU3maCases, PlaceU3ma, {"evil.png", "in/evil.png", "/tmp/u3mscan_hostile_evil.png"}},
  };
  return corpora;
}

class HostileMaterialCorpus : public ::testing::TestWithParam<MaterialCorpus> {};

// One validate run over every bad file of a corpus (a process start costs more than reading a
// file): each file gets its own UNREADABLE block naming the field or entry, and the run ends with
// exit code 2.
TEST_P(HostileMaterialCorpus, ValidateNamesEveryFileAndField) {
  const MaterialCorpus& corpus = GetParam();
  const std::vector<Case>& cases = corpus.cases();
  TempDir tmp;
  std::vector<std::string> args{"validate"};
  for (const Case& c : cases) args.push_back(corpus.place(c.file, tmp.path() / "in").string());
  const RunResult run = RunU3mscan(args, tmp.path() / "tmp");
  ASSERT_TRUE(CleanExit(run, kExitUnreadable, {}));
  for (std::size_t i = 0; i < cases.size(); ++i) {
    const std::string header = args[i + 1] + ": UNREADABLE\n";
    const std::size_t at = run.output.find(header);
    ASSERT_NE(at, std::string::npos) << "no UNREADABLE block for " << args[i + 1] << ":\n" << run.output;
    const std::size_t end = run.output.find("UNREADABLE\n", at + header.size());
    const std::string block = run.output.substr(at, end == std::string::npos ? std::string::npos : end - at);
    EXPECT_NE(block.find(cases[i].mention), std::string::npos) << block;
  }
  EXPECT_TRUE(NothingIn(tmp.path() / "tmp"));
}

INSTANTIATE_TEST_SUITE_P(Corpus, HostileMaterialCorpus, ::testing::ValuesIn(MaterialCorpora()),
                         [](const ::testing::TestParamInfo<MaterialCorpus>& info) { return info.param.name; });

// One bad file of one corpus.
struct MaterialCase {
  std::size_t corpus;  // index in MaterialCorpora()
  Case bad;
};
std::ostream& operator<<(std::ostream& os, const MaterialCase& c) { return os << c.bad; }

std::vector<MaterialCase> MaterialCases() {
  std::vector<MaterialCase> all;
  for (std::size_t i = 0; i < MaterialCorpora().size(); ++i)
    for (const Case& c : MaterialCorpora()[i].cases()) all.push_back({i, c});
  return all;
}

class HostileMaterialFile : public ::testing::TestWithParam<MaterialCase> {};

// `info` and `convert` refuse the file by itself, write no output, and leave nothing in the
// temporary folder (where a package is unpacked, if at all) nor beside it.
TEST_P(HostileMaterialFile, InfoAndConvertRefuseAndWriteNothing) {
  const MaterialCorpus& corpus = MaterialCorpora()[GetParam().corpus];
  const Case& bad = GetParam().bad;
  TempDir tmp;
  const fs::path in = corpus.place(bad.file, tmp.path() / "in");
  const fs::path out = tmp.path() / "out";
  fs::create_directories(out);
  const std::vector<RunResult> runs = RunU3mscanAll({{{"info", in.string()}, tmp.path() / "t1"},
                                                    {{"convert", in.string(), (out / "converted.u3m").string()}, tmp.path() / "t2"}});
  EXPECT_TRUE(CleanExit(runs[0], kExitUnreadable, {in.string(), bad.mention})) << "info";
  EXPECT_TRUE(CleanExit(runs[1], kExitUnreadable, {in.string(), bad.mention})) << "convert";
  EXPECT_TRUE(NothingIn(out));
  EXPECT_TRUE(NothingIn(tmp.path() / "t1"));
  EXPECT_TRUE(NothingIn(tmp.path() / "t2"));
  for (const std::string& escape : corpus.escapes) EXPECT_FALSE(fs::exists(tmp.path() / escape)) << escape;
}

INSTANTIATE_TEST_SUITE_P(Corpus, HostileMaterialFile, ::testing::ValuesIn(MaterialCases()),
                         [](const ::testing::TestParamInfo<MaterialCase>& info) { return FileTestName(info.param.bad.file); });

// ------------------------------------------------------------------------------- capture folders

// A valid capture folder: manifest/valid.json with smooth 16-bit PNG frames.
void WriteValidCapture(const fs::path& dir) {
  fs::create_directories(dir / "frames");
  fs::copy_file(CorpusDir() / "manifest" / "valid.json", dir / "capture.json");
  ImageWriteOptions png;
  png.format = SampleFormat::kUInt16;
  for (const char* name : {"sample_0", "sample_1", "dark"}) {
    Image image(kFrameSide, kFrameSide, 3);
    const float level = std::string(name) == "dark" ? 0.01f : 0.4f;
    for (int c = 0; c < 3; ++c)
      for (int r = 0; r < kFrameSide; ++r)
        for (int x = 0; x < kFrameSide; ++x) image.at(c, r, x) = level * (0.8f + 0.2f * static_cast<float>(x + r) / kFrameSide);
    WriteImageFile(image, dir / "frames" / (std::string(name) + ".png"), png);
  }
}

// Replaces frame 0's file name in capture.json (keeps everything else).
void RenameFrame0(const fs::path& capture, const std::string& new_name) {
  std::string text = ReadFile(capture / "capture.json");
  const std::string old_name = "\"frames/sample_0.png\"";
  text.replace(text.find(old_name), old_name.size(), "\"frames/" + new_name + "\"");
  WriteFile(capture / "capture.json", text);
}

void SetCameraSide(const fs::path& capture, int side) {
  std::string text = ReadFile(capture / "capture.json");
  for (const char* key : {"\"width\": 32", "\"height\": 32"}) {
    const std::size_t at = text.find(key);
    text.replace(at, std::string(key).size(), std::string(key).substr(0, std::string(key).size() - 2) + std::to_string(side));
  }
  WriteFile(capture / "capture.json", text);
}

RunResult Calibrate(const TempDir& tmp, const fs::path& capture) {
  return RunU3mscan({"calibrate", capture.string(), "-o", (tmp.path() / "out").string()}, tmp.path() / "t");
}

// `calibrate` refuses the capture (exit 2, a message with every mention) and writes nothing, neither
// in its output nor in its temporary folder.
void ExpectCalibrateRefuses(const TempDir& tmp, const fs::path& capture, const std::vector<std::string>& mentions) {
  EXPECT_TRUE(CleanExit(Calibrate(tmp, capture), kExitUnreadable, mentions));
  EXPECT_TRUE(NothingIn(tmp.path() / "out"));
  EXPECT_TRUE(NothingIn(tmp.path() / "t"));
}

TEST(HostileCapture, ControlCalibrates) {
  TempDir tmp;
  WriteValidCapture(tmp.path() / "capture");
  EXPECT_TRUE(CleanExit(Calibrate(tmp, tmp.path() / "capture"), kExitOk, {"calibration.json"}));
  EXPECT_TRUE(fs::exists(tmp.path() / "out" / "calibration.json"));
}

const std::vector<Case>& BadManifestCases() {
  static const std::vector<Case> cases = {
      {"truncated.json", "capture.json"},
      {"not_json.json", "capture.json"},
      {"nan_token.json", "capture.json"},
      {"infinity_token.json", "capture.json"},
      {"huge_number.json", "1e400"},  // nlohmann reports no position for an overflow
      {"duplicate_keys.json", "format"},
      {"wrong_type_width.json", "/cameras/0/width"},
      {"wrong_type_frames.json", "/frames"},
      {"negative_exposure.json", "/frames/0/exposure_s"},
      {"enormous_camera.json", "/cameras/0/width"},
      {"traversal_frame.json", "/frames/0/file"},
      {"absolute_frame.json", "/frames/0/file"},
      {"backslash_frame.json", "/frames/0/file"},
      {"missing_frame.json", "/frames/0/file"},
      {"unknown_light.json", "/frames/0/light"},
      {"deep_nesting.json", "capture.json"},  // generated: a vendor key kManifestNestingDepth deep
  };
  return cases;
}

class HostileManifest : public ::testing::TestWithParam<Case> {};

TEST_P(HostileManifest, CalibrateRefusesAndWritesNothing) {
  TempDir tmp;
  const fs::path capture = tmp.path() / "capture";
  WriteValidCapture(capture);
  WriteFile(tmp.path() / "outside.png", ReadFile(capture / "frames" / "sample_0.png"));  // bait for escapes
  if (GetParam().file == "deep_nesting.json") {
    std::string text = ReadFile(capture / "capture.json");
    text = text.substr(0, text.rfind('}')) + ", \"vendor_deep\": " + DeepArray(kManifestNestingDepth) + "}";
    WriteFile(capture / "capture.json", text);
  } else {
    fs::copy_file(CorpusDir() / "manifest" / GetParam().file, capture / "capture.json", fs::copy_options::overwrite_existing);
  }
  ExpectCalibrateRefuses(tmp, capture, {"capture.json", GetParam().mention});
}

INSTANTIATE_TEST_SUITE_P(Corpus, HostileManifest, ::testing::ValuesIn(BadManifestCases()), CaseName);

TEST(HostileManifestExtra, SymlinkOutOfTheFolderIsRefused) {
  TempDir tmp;
  const fs::path capture = tmp.path() / "capture";
  WriteValidCapture(capture);
  fs::rename(capture / "frames" / "sample_0.png", tmp.path() / "outside.png");
  fs::create_symlink("../../outside.png", capture / "frames" / "sample_0.png");
  EXPECT_TRUE(CleanExit(Calibrate(tmp, capture), kExitUnreadable, {"capture.json", "/frames/0/file"}));
  EXPECT_TRUE(NothingIn(tmp.path() / "out"));
}

// Frame 0 as something that is not a regular file inside the folder: a FIFO (reading it would
// block forever), a folder, and a symlink to /dev/zero (endless bytes).
TEST(HostileManifestExtra, SpecialFilesAreRefusedWithoutReading) {
  TempDir tmp;
  std::vector<RunSpec> runs;
  for (const std::string kind : {"fifo", "folder", "dev_zero"}) {
    const fs::path capture = tmp.path() / kind / "capture";
    WriteValidCapture(capture);
    const fs::path frame = capture / "frames" / "sample_0.png";
    fs::remove(frame);
    if (kind == "fifo") {
      ASSERT_EQ(::mkfifo(frame.c_str(), 0644), 0);
    } else if (kind == "folder") {
      fs::create_directories(frame);
    } else {
      fs::create_symlink("/dev/zero", frame);
    }
    runs.push_back({{"calibrate", capture.string(), "-o", (tmp.path() / kind / "out").string()}, tmp.path() / kind / "t"});
  }
  const std::vector<RunResult> results = RunU3mscanAll(runs);
  for (std::size_t i = 0; i < results.size(); ++i) {
    EXPECT_TRUE(CleanExit(results[i], kExitUnreadable, {"capture.json", "/frames/0/file"})) << runs[i].args[1];
    EXPECT_TRUE(NothingIn(runs[i].args[3]));
  }
}

// Frame 0 of a valid capture replaced by a bad image (tests/hostile/images, or made here).
const std::vector<Case>& BadFrameCases() {
  static const std::vector<Case> cases = {
      {"truncated_after_header.png", "truncated_after_header.png"},
      {"corrupt_data.png", "corrupt_data.png"},
      {"text.png", "text.png"},
      {"enormous_dimensions.png", "enormous_dimensions.png"},
      {"truncated.tif", "truncated.tif"},
      {"corrupt.tif", "corrupt.tif"},
      {"truncated.exr", "truncated.exr"},
      {"corrupt.exr", "corrupt.exr"},
      {"truncated.jpg", "truncated.jpg"},
      {"corrupt.jpg", "corrupt.jpg"},
      {"text_named.dng", "text_named.dng"},
      {"tiff_named.nef", "tiff_named.nef"},
      {"truncated.dng", "truncated.dng"},                                      // generated
      {"enormous_matching_camera.png", "enormous_matching_camera.png"},  // camera says 65536 too
  };
  return cases;
}

class HostileFrame : public ::testing::TestWithParam<Case> {};

TEST_P(HostileFrame, CalibrateRefusesAndWritesNothing) {
  TempDir tmp;
  const fs::path capture = tmp.path() / "capture";
  WriteValidCapture(capture);
  const std::string name = GetParam().file;
  const fs::path frame = capture / "frames" / name;
  if (name == "truncated.dng") {
    const Image rgb(kFrameSide, kFrameSide, 3, 0.4f);
    WriteDng(frame, MosaicFromLinearRgb(rgb, CfaPattern::kRggb, 0, 65535), kFrameSide, kFrameSide);
    const std::string bytes = ReadFile(frame);
    WriteFile(frame, bytes.substr(0, bytes.size() / 2));
  } else if (name == "enormous_matching_camera.png") {
    fs::copy_file(CorpusDir() / "images" / "enormous_dimensions.png", frame);
    SetCameraSide(capture, 65536);
  } else {
    fs::copy_file(CorpusDir() / "images" / name, frame);
  }
  fs::remove(capture / "frames" / "sample_0.png");
  RenameFrame0(capture, name);
  ExpectCalibrateRefuses(tmp, capture, {GetParam().mention});
}

INSTANTIATE_TEST_SUITE_P(Corpus, HostileFrame, ::testing::ValuesIn(BadFrameCases()), CaseName);

}  // namespace
}  // namespace u3mscan::hostile

namespace u3mscan::hostile {
namespace {

// `process` (the main job) on a few representative bad captures: a traversal in capture.json, a
// truncated PNG frame and a text file named .dng. The batch driver reports the capture as failed
// (exit 1) with the reason, and writes no material, texture or report for it.
TEST(HostileProcess, BadCapturesFailCleanlyAndWriteNothing) {
  TempDir tmp;
  struct Bad {
    std::string kind, image, manifest, mention;
  };
  const std::vector<Bad> bad = {{"traversal", "", "traversal_frame.json", "/frames/0/file"},
                                {"truncated_png", "truncated_after_header.png", "", "truncated_after_header.png"},
                                {"text_dng", "text_named.dng", "", "text_named.dng"}};
  std::vector<RunSpec> runs;
  for (const Bad& b : bad) {
    const fs::path capture = tmp.path() / b.kind / "capture";
    WriteValidCapture(capture);
    if (!b.manifest.empty())
      fs::copy_file(CorpusDir() / "manifest" / b.manifest, capture / "capture.json", fs::copy_options::overwrite_existing);
    if (!b.image.empty()) {
      fs::copy_file(CorpusDir() / "images" / b.image, capture / "frames" / b.image);
      fs::remove(capture / "frames" / "sample_0.png");
      RenameFrame0(capture, b.image);
    }
    runs.push_back({{"process", capture.string(), "-o", (tmp.path() / b.kind / "out").string(), "--quiet"},
                    tmp.path() / b.kind / "t"});
  }
  const std::vector<RunResult> results = RunU3mscanAll(runs);
  for (std::size_t i = 0; i < bad.size(); ++i) {
    EXPECT_TRUE(CleanExit(results[i], kExitCaptureFailed, {"FAILED", bad[i].mention})) << bad[i].kind;
    EXPECT_TRUE(NothingIn(tmp.path() / bad[i].kind / "out")) << bad[i].kind;
    EXPECT_TRUE(NothingIn(tmp.path() / bad[i].kind / "t")) << bad[i].kind;
  }
}

}  // namespace
}  // namespace u3mscan::hostile
