// The capture manifest (u3m-capture/1): every class of contract violation gives an InputError
// naming the file, the JSON pointer and what was expected; valid manifests round-trip.

#include <gtest/gtest.h>

#include <filesystem>
#include <functional>

#include "capture/manifest.h"
#include "capture_test_util.h"
#include "core/error.h"
#include "u3m/image_io.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using testing::MakeManifest;
using testing::TempDir;

constexpr const char* kSource = "scan/capture.json";

// Parses `doc` after `mutate` and returns the error it must raise.
InputError ErrorOf(const std::function<void(json&)>& mutate) {
  json doc = ManifestToJson(MakeManifest());
  mutate(doc);
  try {
    ParseManifest(doc.dump(), kSource);
  } catch (const InputError& e) {
    return e;
  }
  ADD_FAILURE() << "no InputError for " << doc.dump();
  return InputError("", "", "");
}

// file, pointer and a piece of the expectation: all three parts of the message.
void ExpectError(const InputError& e, const std::string& pointer, const std::string& expected_part) {
  EXPECT_EQ(e.file(), kSource);
  EXPECT_EQ(e.field(), pointer) << e.what();
  EXPECT_NE(e.expected().find(expected_part), std::string::npos) << e.what();
  EXPECT_NE(std::string(e.what()).find(pointer), std::string::npos) << e.what();
}

TEST(Manifest, ValidManifestRoundTrips) {
  Manifest m = MakeManifest();
  m.output.dpi = 600;
  m.output.region_mm = std::array<double, 4>{-10, -10, 10, 10};
  m.sample.thickness_mm = 0.4;
  m.cameras[0].response = SensorResponse{512, 16383};
  m.cameras[0].white_balance = std::array<double, 3>{2.0, 1.0, 1.5};
  LightSpec point;
  point.id = "P";
  point.type = ManifestLightType::kPoint;
  point.position_mm = Eigen::Vector3d(100, 0, 300);
  point.profile = LightProfile{Eigen::Vector3d(0, 0, -1), 2.0};
  m.lights.push_back(point);
  m.targets.board = BoardTarget{7, 5, 10.0, 7.5, "DICT_5X5_100"};
  m.targets.sphere = SphereTarget{12.5, Eigen::Vector3d(0, 0, 12.5)};
  FrameSpec board;
  board.file = "calibration/board.png";
  board.camera = "top";
  board.exposure_s = 0.02;
  board.role = FrameRole::kBoard;
  board.side = "back";
  m.frames.push_back(board);
  m.extra["vendor_acquisition"] = {{"iso", 100}};
  m.frames[0].extra["temperature_c"] = 21.5;

  const json j = ManifestToJson(m);
  const Manifest back = ParseManifest(j.dump(2), kSource);
  EXPECT_EQ(ManifestToJson(back), j);
  EXPECT_EQ(back.lights[2].type, ManifestLightType::kPoint);
  EXPECT_EQ(back.frames[3].role, FrameRole::kBoard);
  EXPECT_EQ(back.frames[3].side, "back");
  EXPECT_FALSE(back.frames[2].light.has_value());
  EXPECT_EQ(back.extra["vendor_acquisition"]["iso"], 100);
  EXPECT_EQ(back.frames[0].extra["temperature_c"], 21.5);
  EXPECT_DOUBLE_EQ(back.cameras[0].response->white_level, 16383);
  EXPECT_TRUE(back.cameras[0].pose->rotation.isApprox(m.cameras[0].pose->rotation));
}

TEST(Manifest, DefaultsForOptionalKeys) {
  json doc = ManifestToJson(MakeManifest());
  doc["frames"][0].erase("side");
  doc["frames"][2].erase("light");
  doc.erase("scanner");
  doc.erase("sample");
  const Manifest m = ParseManifest(doc.dump(), kSource);
  EXPECT_EQ(m.frames[0].side, "front");
  EXPECT_FALSE(m.frames[2].light.has_value());
  // A flat 9-number rotation is accepted as row-major.
  doc["cameras"][0]["pose"]["rotation"] = {1, 0, 0, 0, -1, 0, 0, 0, -1};
  EXPECT_NO_THROW(ParseManifest(doc.dump(), kSource));
}

TEST(ManifestErrors, NotJson) {
  try {
    ParseManifest("{\"format\": ", kSource);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), kSource);
    EXPECT_NE(e.expected().find("valid JSON"), std::string::npos);
  }
}

TEST(ManifestErrors, DuplicateKeysAreRefusedWithTheirPointer) {
  try {
    ParseManifest(R"({"format": "u3m-capture/1", "scanner": {"vendor": "a", "vendor": "b"}})", kSource);
    FAIL() << "a duplicate key was accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), kSource);
    EXPECT_EQ(e.field(), "/scanner/vendor");
    EXPECT_NE(e.expected().find("appears twice"), std::string::npos);
  }
}

TEST(ManifestErrors, DeepNestingIsRefusedBeforeItIsCopied) {
  const std::string deep = std::string(100000, '[') + std::string(100000, ']');
  try {
    ParseManifest(R"({"format": "u3m-capture/1", "vendor_deep": )" + deep + "}", kSource);
    FAIL() << "100000 levels of nesting were accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), kSource);
    EXPECT_NE(e.expected().find("nested at most"), std::string::npos);
  }
}

TEST(ManifestErrors, NumberOverflowIsNotFinite) {
  const std::string text = ManifestToJson(MakeManifest()).dump();
  std::string bad = text;
  bad.replace(bad.find("\"exposure_s\":0.01"), 17, "\"exposure_s\":1e999");
  EXPECT_THROW(ParseManifest(bad, kSource), InputError);
}

TEST(ManifestErrors, RootNotAnObject) {
  try {
    ParseManifest("[1, 2]", kSource);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(e.field(), "/");
  }
}

TEST(ManifestErrors, WrongFormat) {
  ExpectError(ErrorOf([](json& d) { d["format"] = "u3m-capture/2"; }), "/format", "\"u3m-capture/1\", got \"u3m-capture/2\"");
}

TEST(ManifestErrors, MissingFormat) {
  ExpectError(ErrorOf([](json& d) { d.erase("format"); }), "/format", "a required key");
}

TEST(ManifestErrors, UnknownCamera) {
  ExpectError(ErrorOf([](json& d) { d["frames"][1]["camera"] = "side"; }), "/frames/1/camera", "unknown camera \"side\"");
}

TEST(ManifestErrors, UnknownLight) {
  ExpectError(ErrorOf([](json& d) { d["frames"][0]["light"] = "L9"; }), "/frames/0/light", "unknown light \"L9\"");
}

TEST(ManifestErrors, LightWithNeitherPositionNorDirection) {
  ExpectError(ErrorOf([](json& d) { d["lights"][1].erase("direction"); }), "/lights/1/direction",
              "a required key: the unit vector from the sample toward a directional light");
  ExpectError(ErrorOf([](json& d) { d["lights"][0]["type"] = "point"; }), "/lights/0/direction",
              "no direction for a point light");
  ExpectError(ErrorOf([](json& d) {
                d["lights"][0]["type"] = "point";
                d["lights"][0].erase("direction");
              }),
              "/lights/0/position_mm", "a required key");
  ExpectError(ErrorOf([](json& d) { d["lights"][0]["position_mm"] = {0, 0, 100}; }), "/lights/0/position_mm",
              "no position_mm for a directional light");
}

TEST(ManifestErrors, UnknownLightType) {
  ExpectError(ErrorOf([](json& d) { d["lights"][0]["type"] = "spot"; }), "/lights/0/type", "got \"spot\"");
}

TEST(ManifestErrors, NonUnitDirection) {
  ExpectError(ErrorOf([](json& d) { d["lights"][0]["direction"] = {0.6, 0.0, 0.9}; }), "/lights/0/direction",
              "a unit vector");
}

TEST(ManifestErrors, NonPositiveIntensity) {
  ExpectError(ErrorOf([](json& d) { d["lights"][1]["intensity"][2] = 0.0; }), "/lights/1/intensity/2", "> 0");
}

TEST(ManifestErrors, ProfileOnDirectionalLight) {
  ExpectError(ErrorOf([](json& d) { d["lights"][0]["profile"] = {{"axis", {0, 0, -1}}, {"exponent", 1}}; }),
              "/lights/0/profile", "no emitter profile for a directional light");
}

TEST(ManifestErrors, NegativeOrZeroExposure) {
  ExpectError(ErrorOf([](json& d) { d["frames"][1]["exposure_s"] = -0.5; }), "/frames/1/exposure_s",
              "an exposure time in seconds (a number > 0), got -0.5");
  ExpectError(ErrorOf([](json& d) { d["frames"][0]["exposure_s"] = 0; }), "/frames/0/exposure_s", "> 0");
}

TEST(ManifestErrors, UnknownRole) {
  ExpectError(ErrorOf([](json& d) { d["frames"][0]["role"] = "photo"; }), "/frames/0/role",
              "one of the roles sample, ambient, dark, flat, board, sphere, chart, backlight; got \"photo\"");
}

TEST(ManifestErrors, BadSide) {
  ExpectError(ErrorOf([](json& d) { d["frames"][0]["side"] = "top"; }), "/frames/0/side",
              "\"front\" or \"back\", got \"top\"");
}

TEST(ManifestErrors, DuplicateIds) {
  ExpectError(ErrorOf([](json& d) { d["lights"][1]["id"] = "L0"; }), "/lights/1/id", "\"L0\" is used before");
  ExpectError(ErrorOf([](json& d) { d["cameras"].push_back(d["cameras"][0]); }), "/cameras/1/id",
              "\"top\" is used before");
  ExpectError(ErrorOf([](json& d) { d["frames"][1]["file"] = d["frames"][0]["file"]; }), "/frames/1/file",
              "also /frames/0/file");
}

TEST(ManifestErrors, WrongJsonTypes) {
  ExpectError(ErrorOf([](json& d) { d["cameras"][0]["width"] = "64"; }), "/cameras/0/width",
              "an image width in pixels (a number), got a string (\"64\")");
  ExpectError(ErrorOf([](json& d) { d["cameras"][0]["height"] = 64.5; }), "/cameras/0/height", "an integer");
  ExpectError(ErrorOf([](json& d) { d["frames"] = json::object(); }), "/frames", "a JSON array");
  ExpectError(ErrorOf([](json& d) { d["frames"][0]["light"] = 3; }), "/frames/0/light", "a light id");
  ExpectError(ErrorOf([](json& d) { d["cameras"][0]["distortion"] = {0, 0, 0}; }), "/cameras/0/distortion",
              "an array of 5 numbers");
  ExpectError(ErrorOf([](json& d) { d["lights"][0]["direction"][1] = nullptr; }), "/lights/0/direction/1",
              "(a number), got null");
}

TEST(ManifestErrors, UnknownKeyInClosedObject) {
  ExpectError(ErrorOf([](json& d) { d["cameras"][0]["intrinsics"]["fz"] = 1; }), "/cameras/0/intrinsics/fz",
              "one of the keys {cx, cy, fx, fy}");
}

TEST(ManifestErrors, PathsOutsideTheFolder) {
  ExpectError(ErrorOf([](json& d) { d["frames"][0]["file"] = "/data/frame.png"; }), "/frames/0/file", "absolute path");
  ExpectError(ErrorOf([](json& d) { d["frames"][0]["file"] = "frames/../../x.png"; }), "/frames/0/file", "no \"..\"");
  ExpectError(ErrorOf([](json& d) { d["frames"][0]["file"] = "frames\\a.png"; }), "/frames/0/file", "'/' separators");
  ExpectError(ErrorOf([](json& d) { d["frames"][0]["file"] = "frames//a.png"; }), "/frames/0/file", "normalised");
}

TEST(ManifestErrors, RoleNeedsItsTarget) {
  ExpectError(ErrorOf([](json& d) {
                d["frames"].push_back({{"file", "b.png"}, {"camera", "top"}, {"light", nullptr},
                                       {"exposure_s", 0.1}, {"role", "board"}});
              }),
              "/frames/3/role", "a /targets/board description for a board frame");
  ExpectError(ErrorOf([](json& d) {
                d["frames"].push_back({{"file", "f.png"}, {"camera", "top"}, {"light", "L0"},
                                       {"exposure_s", 0.1}, {"role", "flat"}});
              }),
              "/frames/3/role", "/targets/white");
}

TEST(ManifestErrors, RoleAndLightDisagree) {
  ExpectError(ErrorOf([](json& d) { d["frames"][0]["light"] = nullptr; }), "/frames/0/light",
              "the id of the light that lights this sample frame");
  ExpectError(ErrorOf([](json& d) { d["frames"][2]["light"] = "L0"; }), "/frames/2/light", "null for a dark frame");
}

TEST(ManifestErrors, NoSampleFrame) {
  ExpectError(ErrorOf([](json& d) {
                d["frames"].erase(0);
                d["frames"].erase(0);
              }),
              "/frames", "at least one frame with role \"sample\"");
}

TEST(ManifestErrors, NotARotation) {
  ExpectError(ErrorOf([](json& d) { d["cameras"][0]["pose"]["rotation"] = {{1, 0, 0}, {0, 1, 0}, {0, 0, -1}}; }),
              "/cameras/0/pose/rotation", "a proper rotation matrix");
}

TEST(ManifestErrors, ResponseLevels) {
  ExpectError(ErrorOf([](json& d) { d["cameras"][0]["response"] = {{"black_level", 600}, {"white_level", 500}}; }),
              "/cameras/0/response/white_level", "a white level above the black level");
}

TEST(ManifestErrors, BoardTargetChecks) {
  ExpectError(ErrorOf([](json& d) {
                d["targets"]["board"] = {{"squares_x", 5}, {"squares_y", 7}, {"square_mm", 10},
                                         {"marker_mm", 7}, {"dictionary", "DICT_9X9_50"}};
              }),
              "/targets/board/dictionary", "an OpenCV ArUco dictionary name");
  ExpectError(ErrorOf([](json& d) { d["targets"]["white"] = {{"reflectance", 1.5}}; }), "/targets/white/reflectance",
              "a reflectance in (0, 1]");
}

TEST(ManifestErrors, OutputRegion) {
  ExpectError(ErrorOf([](json& d) { d["output"] = {{"region_mm", {0, 0, -1, 5}}}; }), "/output/region_mm",
              "x1 > x0");
}

// ---- ReadManifest: the checks that need the folder ----

class ManifestFolder : public ::testing::Test {
 protected:
  void SetUp() override {
    manifest_ = MakeManifest();
    WriteFrames(64, 64);
  }
  void WriteFrames(int w, int h) {
    for (const auto& f : manifest_.frames) {
      fs::create_directories((dir_.path() / f.file).parent_path());
      WriteImageFile(Image(w, h, 3, 0.25f), dir_.path() / f.file, {SampleFormat::kUInt8, PixelEncoding::kSrgb});
    }
  }
  InputError ReadError() {
    WriteManifest(manifest_, dir_.path());
    try {
      ReadManifest(dir_.path());
    } catch (const InputError& e) {
      return e;
    }
    ADD_FAILURE() << "ReadManifest accepted the folder";
    return InputError("", "", "");
  }
  TempDir dir_;
  Manifest manifest_;
};

TEST_F(ManifestFolder, ReadsAValidFolder) {
  WriteManifest(manifest_, dir_.path());
  const Manifest m = ReadManifest(dir_.path());
  EXPECT_EQ(m.frames.size(), 3u);
  EXPECT_EQ(ManifestToJson(m), ManifestToJson(manifest_));
  EXPECT_NO_THROW(ReadManifest(dir_.path() / "capture.json"));  // the file itself also works
}

TEST_F(ManifestFolder, MissingFrameFile) {
  fs::remove(dir_.path() / manifest_.frames[1].file);
  const InputError e = ReadError();
  EXPECT_EQ(e.file(), (dir_.path() / "capture.json").string());
  EXPECT_EQ(e.field(), "/frames/1/file");
  EXPECT_NE(e.expected().find("an existing frame file, \"frames/sample_1.png\""), std::string::npos) << e.what();
}

TEST_F(ManifestFolder, FrameSizeDiffersFromCamera) {
  WriteImageFile(Image(64, 48, 3, 0.25f), dir_.path() / manifest_.frames[2].file, {SampleFormat::kUInt8, PixelEncoding::kSrgb});
  const InputError e = ReadError();
  EXPECT_EQ(e.field(), "/frames/2/file");
  EXPECT_NE(e.expected().find("camera \"top\"'s size 64x64, \"frames/dark.png\" is 64x48"), std::string::npos) << e.what();
}

TEST_F(ManifestFolder, FrameThatIsNotAnImage) {
  testing::WriteText(dir_.path() / manifest_.frames[0].file, "not a png");
  const InputError e = ReadError();
  EXPECT_EQ(e.field(), "/frames/0/file");
  EXPECT_NE(e.expected().find("a readable image file"), std::string::npos) << e.what();
}

TEST_F(ManifestFolder, SymlinkOutOfTheFolder) {
  TempDir outside_dir;
  const fs::path outside = outside_dir.path() / "x.png";
  WriteImageFile(Image(64, 64, 3, 0.25f), outside, {SampleFormat::kUInt8, PixelEncoding::kSrgb});
  fs::remove(dir_.path() / manifest_.frames[0].file);
  fs::create_symlink(outside, dir_.path() / manifest_.frames[0].file);
  const InputError e = ReadError();
  EXPECT_EQ(e.field(), "/frames/0/file");
  EXPECT_NE(e.expected().find("inside the capture folder"), std::string::npos) << e.what();
}

TEST_F(ManifestFolder, NoManifest) {
  try {
    ReadManifest(dir_.path());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), (dir_.path() / "capture.json").string());
  }
}

TEST_F(ManifestFolder, WriteRefusesAnInvalidManifestAndWritesNothing) {
  manifest_.frames[0].exposure_s = -1.0;
  try {
    WriteManifest(manifest_, dir_.path());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(e.field(), "/frames/0/exposure_s");
  }
  EXPECT_FALSE(fs::exists(dir_.path() / "capture.json"));
  EXPECT_FALSE(fs::exists(dir_.path() / ".capture.json.partial"));
}

TEST_F(ManifestFolder, WriteReplacesAtomically) {
  WriteManifest(manifest_, dir_.path());
  manifest_.sample.name = "second";
  WriteManifest(manifest_, dir_.path());
  EXPECT_EQ(ReadManifest(dir_.path()).sample.name, "second");
  EXPECT_FALSE(fs::exists(dir_.path() / ".capture.json.partial"));
}

}  // namespace
}  // namespace u3mscan
