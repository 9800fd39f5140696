#include "datasets_synthetic/capture_writer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iterator>
#include <map>
#include <set>
#include <unistd.h>
#include <thread>
#include <chrono>
#include <nlohmann/json.hpp>

#include "capture/frame_decoder.h"
#include "capture/manifest.h"
#include "core/error.h"
#include "datasets_synthetic/renderer.h"
#include "datasets_synthetic/sensor.h"
#include "test_scenes.h"

namespace u3mscan::synthetic {
namespace {

namespace fs = std::filesystem;

constexpr int kSize = 64;
constexpr int kSceneSize = 48;
constexpr std::uint64_t kSeed = 11;

class CaptureWriterTest : public ::testing::Test {
 protected:
  void SetUp() override {
    // The pid keeps concurrent runs (ctest -j, other checkouts) out of each other's folders.
    root_ = fs::temp_directory_path() / ("u3mscan_synth_writer_" + std::to_string(::getpid()) + "_" +
                                         ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(root_);
    fs::create_directories(root_);
    RigOptions options;
    options.width = options.height = kSize;
    options.seed = kSeed;
    rig_ = MakeRig("near", options);
    scene_ = testing::FlatScene(kSceneSize, kSceneSize, rig_.ground_pitch_mm, 0.5f);
    // A coloured sample so that channel mix-ups show.
    for (float& v : scene_.base_color.plane(0)) v = 0.6f;
    for (float& v : scene_.base_color.plane(2)) v = 0.3f;
  }
  void TearDown() override { fs::remove_all(root_); }

  fs::path Write(const std::string& name, FrameFormat format, bool calibration = false) {
    CaptureOptions options;
    options.format = format;
    options.calibration_frames = calibration;
    const fs::path dir = root_ / name;
    WriteSyntheticCapture(scene_, rig_, options, dir);
    return dir;
  }

  // The renderer's linear value of the top camera under light 0, ambient included.
  Image Expected() const {
    SceneRenderer renderer(scene_, rig_);
    renderer.SetCamera(0);
    Image img = renderer.RenderLight(0);
    const Image amb = renderer.RenderAmbient();
    for (std::size_t i = 0; i < img.data().size(); ++i) img.data()[i] += amb.data()[i];
    return img;
  }

  // Pixels well inside the sample (away from the sample/table edge where demosaicing blends).
  bool Interior(int row, int col) const {
    constexpr int kMargin = 12;
    return row >= kMargin && row < kSize - kMargin && col >= kMargin && col < kSize - kMargin;
  }

  fs::path root_;
  Rig rig_;
  SceneTruth scene_;
};

TEST_F(CaptureWriterTest, WrittenManifestPassesReadManifestWithEveryRole) {
  scene_.alpha.at(0, 20, 20) = 0.0f;  // a hole, so the backlight frame is written too
  const fs::path dir = Write("all", FrameFormat::kDng, true);
  const Manifest m = ReadManifest(dir / kCaptureSubdir);
  EXPECT_EQ(m.cameras.size(), 1u);
  EXPECT_EQ(m.lights.size(), rig_.lights.size());
  std::set<FrameRole> roles;
  for (const FrameSpec& f : m.frames) roles.insert(f.role);
  for (FrameRole r : {FrameRole::kSample, FrameRole::kAmbient, FrameRole::kDark, FrameRole::kFlat, FrameRole::kBoard,
                      FrameRole::kSphere, FrameRole::kChart, FrameRole::kBacklight}) {
    EXPECT_TRUE(roles.count(r)) << FrameRoleName(r);
  }
  ASSERT_TRUE(m.targets.board.has_value());
  ASSERT_TRUE(m.output.dpi.has_value());
  EXPECT_NEAR(*m.output.dpi, 25.4 / rig_.ground_pitch_mm, 1e-9);
  std::ifstream in(dir / kTruthSubdir / kTruthFileName);
  const nlohmann::json truth = nlohmann::json::parse(in);
  EXPECT_EQ(truth.at("rig").at("lights").size(), rig_.lights.size());
  EXPECT_EQ(truth.at("rig").at("units").at("length"), "mm");
  // Nothing but DIR itself appears next to it.
  int entries = 0;
  for (const auto& e : fs::directory_iterator(root_)) entries += e.path().filename() == "all" ? 1 : 100;
  EXPECT_EQ(entries, 1);
}

// A scanner that takes only its radiometric calibration (dark, a flat per light): those frames and
// the white target are written, no board, sphere or chart frames nor their targets.
TEST_F(CaptureWriterTest, ChosenCalibrationRolesAreTheOnlyOnesWritten) {
  CaptureOptions options;
  options.format = FrameFormat::kTiff;
  options.calibration_roles = {FrameRole::kDark, FrameRole::kFlat};
  const fs::path dir = root_ / "flats";
  WriteSyntheticCapture(scene_, rig_, options, dir);
  const Manifest m = ReadManifest(dir / kCaptureSubdir);
  std::map<FrameRole, int> count;
  for (const FrameSpec& f : m.frames) ++count[f.role];
  EXPECT_EQ(count[FrameRole::kSample], static_cast<int>(rig_.lights.size()));
  EXPECT_EQ(count[FrameRole::kFlat], static_cast<int>(rig_.lights.size()));
  EXPECT_EQ(count[FrameRole::kDark], 1);
  for (FrameRole r : {FrameRole::kBoard, FrameRole::kSphere, FrameRole::kChart, FrameRole::kBacklight}) {
    EXPECT_EQ(count[r], 0) << FrameRoleName(r);
  }
  EXPECT_TRUE(m.targets.white.has_value());
  EXPECT_FALSE(m.targets.board.has_value());
  EXPECT_FALSE(m.targets.sphere.has_value());
  EXPECT_FALSE(m.targets.chart.has_value());
}

TEST(CalibrationRolesFromList, ParsesNamesAndAllAndRejectsTheRestNamingTheOption) {
  EXPECT_EQ(CalibrationRolesFromList("dark,flat", "--calibration-frames"),
            (std::set<FrameRole>{FrameRole::kDark, FrameRole::kFlat}));
  EXPECT_EQ(CalibrationRolesFromList("all", "--calibration-frames"), AllCalibrationRoles());
  EXPECT_EQ(AllCalibrationRoles().size(), 6u);
  for (const char* bad : {"dark,flats", "sample", "", "flat,"}) {
    try {
      CalibrationRolesFromList(bad, "--calibration-frames");
      ADD_FAILURE() << "accepted '" << bad << "'";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("--calibration-frames"), std::string::npos) << e.what();
    }
  }
}

TEST_F(CaptureWriterTest, ObliqueRigWithoutPosesPassesReadManifest) {
  RigOptions options;
  options.width = options.height = kSize;
  rig_ = MakeRig("oblique", options);
  CaptureOptions capture;
  capture.format = FrameFormat::kExr;
  capture.write_pose = false;
  const fs::path dir = root_ / "oblique";
  WriteSyntheticCapture(scene_, rig_, capture, dir);
  const Manifest m = ReadManifest(dir / kCaptureSubdir);
  ASSERT_EQ(m.cameras.size(), 2u);
  int oblique_boards = 0;
  for (const CameraSpec& c : m.cameras) EXPECT_FALSE(c.pose.has_value()) << c.id;
  for (const FrameSpec& f : m.frames) oblique_boards += f.camera == "oblique" && f.role == FrameRole::kBoard;
  EXPECT_EQ(oblique_boards, 1);
}

// libraw decodes the DNG (AHD demosaic) back to the renderer's values within the sensor's noise.
TEST_F(CaptureWriterTest, DngDecodedByLibrawMatchesRendererValues) {
  const fs::path dir = Write("dng", FrameFormat::kDng);
  const Manifest m = ReadManifest(dir / kCaptureSubdir);
  const FrameSpec& frame = m.frames.at(0);
  ASSERT_EQ(frame.light.value(), rig_.lights[0].id);
  FrameDecodeOptions decode;
  decode.white_balance = m.cameras[0].white_balance;
  const DecodedFrame decoded = DecodeFrame(dir / kCaptureSubdir / frame.file, decode);
  const Image expected = Expected();
  ASSERT_EQ(decoded.rgb.width(), kSize);
  for (int c = 0; c < 3; ++c) {
    double sum_diff = 0, sum_sq = 0, sum_sigma2 = 0;
    int n = 0;
    for (int r = 0; r < kSize; ++r)
      for (int col = 0; col < kSize; ++col) {
        if (!Interior(r, col)) continue;
        const double e = expected.at(c, r, col), d = decoded.rgb.at(c, r, col) - e;
        sum_diff += d;
        sum_sq += d * d;
        sum_sigma2 += std::pow(NoiseSigma(rig_.sensor, e), 2);
        ++n;
      }
    const double sigma = std::sqrt(sum_sigma2 / n);
    // Demosaicing averages neighbours (less noise) but also interpolates (a little bias at
    // gradients): the mean within 5 standard errors plus one quantisation step, the per-pixel RMS
    // within twice the sensor noise.
    const double quantum = 1.0 / (rig_.sensor.white_level_dn - rig_.sensor.black_level_dn);
    EXPECT_NEAR(sum_diff / n, 0.0, 5 * sigma / std::sqrt(n) + quantum) << "channel " << c;
    EXPECT_LT(std::sqrt(sum_sq / n), 2 * sigma) << "channel " << c;
  }
}

TEST_F(CaptureWriterTest, TiffExrAndDngOfOneSceneAgree) {
  const fs::path dng = Write("dng", FrameFormat::kDng), tif = Write("tif", FrameFormat::kTiff),
                 exr = Write("exr", FrameFormat::kExr);
  auto decode = [](const fs::path& dir) {
    const Manifest m = ReadManifest(dir / kCaptureSubdir);
    FrameDecodeOptions options;
    options.response = m.cameras[0].response;
    options.white_balance = m.cameras[0].white_balance;
    return DecodeFrame(dir / kCaptureSubdir / m.frames.at(0).file, options).rgb;
  };
  const Image a = decode(dng), b = decode(tif), c = decode(exr);
  // TIFF and EXR hold the same sensor values (same noise stream), TIFF rounded to 16 bits.
  constexpr double kTiffQuantum = 1.0 / 65535.0;
  for (std::size_t i = 0; i < b.data().size(); ++i) ASSERT_NEAR(b.data()[i], c.data()[i], kTiffQuantum) << i;
  // The DNG went through a mosaic and a demosaic: its interior means agree within the noise.
  const double sigma = NoiseSigma(rig_.sensor, 0.3);
  for (int ch = 0; ch < 3; ++ch) {
    double sa = 0, sc = 0;
    int n = 0;
    for (int r = 0; r < kSize; ++r)
      for (int col = 0; col < kSize; ++col) {
        if (!Interior(r, col)) continue;
        sa += a.at(ch, r, col);
        sc += c.at(ch, r, col);
        ++n;
      }
    EXPECT_NEAR(sa / n, sc / n, 6 * sigma / std::sqrt(n)) << "channel " << ch;
  }
}

void ExpectSameFiles(const fs::path& a, const fs::path& b) {
  int files = 0;
  for (const auto& entry : fs::recursive_directory_iterator(a)) {
    if (!entry.is_regular_file()) continue;
    const fs::path rel = fs::relative(entry.path(), a);
    std::ifstream fa(entry.path(), std::ios::binary), fb(b / rel, std::ios::binary);
    ASSERT_TRUE(fb.good()) << rel;
    const std::string ca((std::istreambuf_iterator<char>(fa)), {}), cb((std::istreambuf_iterator<char>(fb)), {});
    EXPECT_TRUE(ca == cb) << rel;
    ++files;
  }
  EXPECT_GT(files, 10);
}

// TIFF and EXR containers stamp the time unless told otherwise; a second apart they must not.
TEST_F(CaptureWriterTest, SameSeedGivesIdenticalTiffAndExrFiles) {
  const fs::path a = Write("a_tif", FrameFormat::kTiff), c = Write("a_exr", FrameFormat::kExr);
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));
  ExpectSameFiles(a, Write("b_tif", FrameFormat::kTiff));
  ExpectSameFiles(c, Write("b_exr", FrameFormat::kExr));
}

TEST_F(CaptureWriterTest, SameSeedGivesIdenticalFiles) {
  const fs::path a = Write("a", FrameFormat::kDng, true), b = Write("b", FrameFormat::kDng, true);
  int files = 0;
  for (const auto& entry : fs::recursive_directory_iterator(a)) {
    if (!entry.is_regular_file()) continue;
    const fs::path rel = fs::relative(entry.path(), a);
    std::ifstream fa(entry.path(), std::ios::binary), fb(b / rel, std::ios::binary);
    ASSERT_TRUE(fb.good()) << rel;
    const std::string ca((std::istreambuf_iterator<char>(fa)), {}), cb((std::istreambuf_iterator<char>(fb)), {});
    EXPECT_TRUE(ca == cb) << rel;
    ++files;
  }
  EXPECT_GT(files, 2 * static_cast<int>(rig_.lights.size()));
  // Another seed changes the noise.
  rig_.seed = kSeed + 1;
  const fs::path c = Write("c", FrameFormat::kDng);
  std::ifstream fa(a / kCaptureSubdir / "frames/top/L00.dng", std::ios::binary), fc(c / kCaptureSubdir / "frames/top/L00.dng", std::ios::binary);
  const std::string ca((std::istreambuf_iterator<char>(fa)), {}), cc((std::istreambuf_iterator<char>(fc)), {});
  EXPECT_FALSE(ca == cc);
}

// Maps a hand-made scene leaves empty are rendered with defaults and written as such.
TEST_F(CaptureWriterTest, SceneWithEmptyMapsStillWritesItsTruth) {
  scene_.tangent = Image();
  scene_.sheen = Image();
  const fs::path dir = Write("sparse", FrameFormat::kExr);
  EXPECT_TRUE(fs::exists(dir / kTruthSubdir / "tangent.exr"));
  EXPECT_TRUE(fs::exists(dir / kTruthSubdir / "sheen.exr"));
}

TEST_F(CaptureWriterTest, FailureLeavesNoPartialOutput) {
  const fs::path dir = root_ / "failed";
  CaptureOptions options;
  options.calibration_frames = false;
  EXPECT_THROW(WriteSyntheticCapture(scene_, rig_, options, dir,
                                     [](const SceneTruth&, const nlohmann::json&, const fs::path&) { throw std::runtime_error("disk full"); }),
               std::runtime_error);
  EXPECT_FALSE(fs::exists(dir));
  EXPECT_TRUE(fs::is_empty(root_));
  // A folder that holds something is refused before anything is written.
  fs::create_directories(dir);
  std::ofstream(dir / "keep.txt") << "mine";
  EXPECT_THROW(WriteSyntheticCapture(scene_, rig_, options, dir), InputError);
  EXPECT_TRUE(fs::exists(dir / "keep.txt"));
  EXPECT_FALSE(fs::exists(dir / kCaptureSubdir));
}

}  // namespace
}  // namespace u3mscan::synthetic
