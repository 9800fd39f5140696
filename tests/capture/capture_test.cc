// Capture: a checked folder with lazy frame access, normalisation, listing and region reads.

#include <gtest/gtest.h>

#include <algorithm>
#include <thread>

#include "capture/capture.h"
#include "capture/dng_writer.h"
#include "capture_test_util.h"
#include "core/error.h"
#include "u3m/image_io.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;
using testing::MakeManifest;
using testing::SmoothRgb;
using testing::TempDir;

constexpr int kSize = 64;
constexpr std::uint16_t kBlack = 256;
constexpr std::uint16_t kWhite = 4095;  // a 12-bit sensor
constexpr double kRawStep = 1.0 / (kWhite - kBlack);
constexpr double k16BitStep = 1.0 / 65535.0;

// A folder with DNG sample frames (one per light), a TIFF ambient frame on the back side and a
// DNG dark frame. Frame i holds a flat value per channel so normalisation is easy to check.
class CaptureFolder : public ::testing::Test {
 protected:
  void SetUp() override {
    manifest_ = MakeManifest(kSize, kSize, ".dng");
    manifest_.cameras[0].response = SensorResponse{kBlack, kWhite};
    FrameSpec ambient;
    ambient.file = "frames/ambient_back.tif";
    ambient.camera = "top";
    ambient.side = "back";
    ambient.exposure_s = 0.5;
    ambient.role = FrameRole::kAmbient;
    manifest_.frames.push_back(ambient);
    for (std::size_t i = 0; i < manifest_.frames.size(); ++i) {
      const FrameSpec& f = manifest_.frames[i];
      const fs::path path = dir_.path() / f.file;
      fs::create_directories(path.parent_path());
      const Image rgb = FrameContent(i);
      if (path.extension() == ".dng") {
        DngWriteOptions opt;
        opt.black_level = kBlack;
        opt.white_level = kWhite;
        WriteDng(path, MosaicFromLinearRgb(rgb, opt.pattern, kBlack, kWhite), kSize, kSize, opt);
      } else {
        // A 16-bit TIFF of the same sensor: code = black + v * (white - black), in 16-bit codes.
        Image coded(kSize, kSize, 3);
        for (int k = 0; k < 3; ++k) {
          for (std::size_t p = 0; p < rgb.pixel_count(); ++p) {
            coded.plane(k)[p] = static_cast<float>((kBlack + rgb.plane(k)[p] * (kWhite - kBlack)) / 65535.0);
          }
        }
        WriteImageFile(coded, path, {SampleFormat::kUInt16, PixelEncoding::kLinear});
      }
    }
    WriteManifest(manifest_, dir_.path());
  }

  static Image FrameContent(std::size_t i) {
    if (i == 0) return SmoothRgb(kSize, kSize, 0.1f, 0.6f);
    Image img(kSize, kSize, 3);
    const float v[3] = {0.1f * (i + 1), 0.08f * (i + 1), 0.05f * (i + 1)};
    for (int k = 0; k < 3; ++k) std::fill(img.plane(k).begin(), img.plane(k).end(), v[k]);
    return img;
  }

  TempDir dir_;
  Manifest manifest_;
};

TEST_F(CaptureFolder, OpensAndListsFrames) {
  const Capture capture = Capture::Open(dir_.path());
  EXPECT_EQ(capture.frame_count(), 4u);
  EXPECT_EQ(capture.FramesWithRole(FrameRole::kSample), (std::vector<std::size_t>{0, 1}));
  EXPECT_EQ(capture.FramesWithRole(FrameRole::kDark), (std::vector<std::size_t>{2}));
  EXPECT_EQ(capture.FramesOfLight("L1"), (std::vector<std::size_t>{1}));
  EXPECT_EQ(capture.FramesOnSide("back"), (std::vector<std::size_t>{3}));
  EXPECT_EQ(capture.FramesOfCamera("top").size(), 4u);
  FrameFilter off;
  off.lights_off = true;
  EXPECT_EQ(capture.Frames(off), (std::vector<std::size_t>{2, 3}));
  FrameFilter front_samples;
  front_samples.role = FrameRole::kSample;
  front_samples.side = "front";
  EXPECT_EQ(capture.Frames(front_samples).size(), 2u);
  EXPECT_EQ(capture.FrameLight(2), nullptr);
  EXPECT_EQ(capture.FrameLight(1)->id, "L1");
  EXPECT_EQ(capture.FramePath(3), dir_.path() / "frames/ambient_back.tif");
  EXPECT_EQ(capture.cached_bytes(), 0u);  // opening decodes nothing
}

TEST_F(CaptureFolder, RefusesAnInvalidFolder) {
  fs::remove(dir_.path() / manifest_.frames[1].file);
  EXPECT_THROW(Capture::Open(dir_.path()), InputError);
}

TEST_F(CaptureFolder, ResponseAppliesToRawAndTiffAlike) {
  const Capture capture = Capture::Open(dir_.path());
  const DecodedFrame dng = capture.LoadFrame(1);
  const DecodedFrame tif = capture.LoadFrame(3);
  EXPECT_NEAR(dng.rgb.at(0, 20, 20), 0.2, kRawStep);
  EXPECT_NEAR(dng.rgb.at(2, 20, 20), 0.1, kRawStep);
  // The TIFF holds 12-bit sensor codes in 16 bits: one raw step of rounding.
  EXPECT_NEAR(tif.rgb.at(0, 20, 20), 0.4, kRawStep + k16BitStep * 65535.0 / (kWhite - kBlack));
}

TEST_F(CaptureFolder, NormalisesByExposureAndIntensity) {
  const Capture capture = Capture::Open(dir_.path());
  const DecodedFrame plain = capture.LoadFrame(1);
  FrameLoadOptions by_exposure;
  by_exposure.divide_by_exposure = true;
  FrameLoadOptions by_both = by_exposure;
  by_both.divide_by_intensity = true;
  const DecodedFrame e = capture.LoadFrame(1, by_exposure);
  const DecodedFrame b = capture.LoadFrame(1, by_both);
  const double exposure_s = manifest_.frames[1].exposure_s;        // 0.02
  const Eigen::Vector3d intensity = manifest_.lights[1].intensity_rgb;  // (1, 1, 0.8)
  constexpr double kRelative = 1e-6;
  for (int k = 0; k < 3; ++k) {
    const double v = plain.rgb.at(k, 7, 9);
    EXPECT_NEAR(e.rgb.at(k, 7, 9), v / exposure_s, kRelative * v / exposure_s);
    EXPECT_NEAR(b.rgb.at(k, 7, 9), v / exposure_s / intensity[k], kRelative * v / exposure_s);
  }
  // A lights-off frame has no intensity to divide by: only the exposure applies.
  const DecodedFrame dark = capture.LoadFrame(2, by_both);
  EXPECT_NEAR(dark.rgb.at(0, 0, 0), capture.LoadFrame(2).rgb.at(0, 0, 0) / manifest_.frames[2].exposure_s, 1e-4);
}

TEST_F(CaptureFolder, RegionsEqualCropsOfFullFrames) {
  const Capture capture = Capture::Open(dir_.path());
  FrameLoadOptions norm;
  norm.divide_by_exposure = true;
  norm.divide_by_intensity = true;
  for (std::size_t index : {std::size_t{0}, std::size_t{3}}) {  // a DNG and a TIFF
    const DecodedFrame full = capture.LoadFrame(index, norm);
    const int x = 5, y = 17, w = 50, h = 20;
    const DecodedFrame part = capture.LoadFrameRegion(index, x, y, w, h, norm);
    for (int k = 0; k < 3; ++k) {
      for (int r = 0; r < h; ++r) {
        for (int c = 0; c < w; ++c) ASSERT_EQ(part.rgb.at(k, r, c), full.rgb.at(k, y + r, x + c)) << index;
      }
    }
    // Row bands tile the frame exactly.
    for (int band = 0; band < kSize; band += 24) {
      const int rows = std::min(24, kSize - band);
      const DecodedFrame rows_frame = capture.LoadFrameRows(index, band, rows, norm);
      ASSERT_EQ(rows_frame.rgb.width(), kSize);
      for (int r = 0; r < rows; ++r) ASSERT_EQ(rows_frame.rgb.at(1, r, 33), full.rgb.at(1, band + r, 33));
    }
  }
  EXPECT_THROW(capture.LoadFrameRegion(0, 40, 0, 30, 10), std::out_of_range);
  EXPECT_THROW(capture.LoadFrame(99), std::out_of_range);
}

TEST_F(CaptureFolder, RawDecodesAreCachedWithinTheBudget) {
  const std::size_t frame_bytes = static_cast<std::size_t>(kSize) * kSize * 7;  // 16-bit RGB + mask
  CaptureOptions options;
  options.decode_cache_bytes = frame_bytes * 3 / 2;  // room for one RAW frame
  const Capture capture = Capture::Open(dir_.path(), options);
  capture.LoadFrameRegion(0, 0, 0, 8, 8);
  EXPECT_EQ(capture.cached_bytes(), frame_bytes);
  capture.LoadFrameRegion(1, 0, 0, 8, 8);
  EXPECT_EQ(capture.cached_bytes(), frame_bytes);  // full: frame 0 kept, frame 1 decoded uncached
  EXPECT_EQ(capture.frames_read_by_region(), 1u);   // and read by region from then on
  // Sweeps of row bands over both RAW frames (as the tiled pipeline reads them): the cache never
  // exceeds its bound, and every read gives the frame's own rows.
  const DecodedFrame full0 = capture.LoadFrame(0), full1 = capture.LoadFrame(1);
  for (int sweep = 0; sweep < 2; ++sweep)
    for (int band = 0; band < kSize; band += 16)
      for (std::size_t index : {std::size_t{0}, std::size_t{1}}) {
        const DecodedFrame part = capture.LoadFrameRows(index, band, 16);
        const DecodedFrame& full = index == 0 ? full0 : full1;
        EXPECT_EQ(part.rgb.at(2, 3, 40), full.rgb.at(2, band + 3, 40));
        EXPECT_LE(capture.cached_bytes(), options.decode_cache_bytes);
      }
  EXPECT_EQ(capture.cached_bytes(), frame_bytes);
  capture.LoadFrameRegion(3, 0, 0, 8, 8);  // a zip TIFF is kept whole too, but the cache is full
  EXPECT_EQ(capture.cached_bytes(), frame_bytes);
  EXPECT_EQ(capture.frames_read_by_region(), 2u);
  capture.ReleaseCache();
  EXPECT_EQ(capture.cached_bytes(), 0u);
  EXPECT_EQ(capture.frames_read_by_region(), 0u);  // room again

  CaptureOptions none;
  none.decode_cache_bytes = 0;
  const Capture uncached = Capture::Open(dir_.path(), none);
  uncached.LoadFrameRegion(0, 0, 0, 8, 8);
  EXPECT_EQ(uncached.cached_bytes(), 0u);
}

TEST(CaptureKeptWholeFrames, RegionReadsDecodeEachPngOrZipTiffOnceAndGiveTheFilesRows) {
  // PNG decodes from the top row, so a row band's read costs the rows above it too, and a zip
  // TIFF's strips are inflated again on every sweep: Capture keeps such frames whole
  // (CompactFrame) within the same budget as RAW ones.
  for (const std::string ext : {".png", ".tif"}) {
    TempDir dir;
    Manifest manifest = MakeManifest(kSize, kSize, ext);
    for (std::size_t i = 0; i < manifest.frames.size(); ++i) {
      const fs::path path = dir.path() / manifest.frames[i].file;
      fs::create_directories(path.parent_path());
      WriteImageFile(SmoothRgb(kSize, kSize, 0.05f * (i + 1), 0.9f), path, {SampleFormat::kUInt16, PixelEncoding::kLinear});
    }
    WriteManifest(manifest, dir.path());
    const std::size_t frame_bytes = static_cast<std::size_t>(kSize) * kSize * 7 + 65536 * sizeof(float);
    const Capture capture = Capture::Open(dir.path());
    CaptureOptions none;
    none.decode_cache_bytes = 0;
    const Capture uncached = Capture::Open(dir.path(), none);
    FrameLoadOptions norm;
    norm.divide_by_exposure = true;
    for (int sweep = 0; sweep < 2; ++sweep)
      for (int band = 0; band < kSize; band += 16)
        for (std::size_t index = 0; index < manifest.frames.size(); ++index) {
          const DecodedFrame part = capture.LoadFrameRows(index, band, 16, norm);
          const DecodedFrame read = uncached.LoadFrameRows(index, band, 16, norm);
          for (int k = 0; k < 3; ++k)
            for (int r = 0; r < 16; ++r)
              for (int c = 0; c < kSize; ++c) ASSERT_EQ(part.rgb.at(k, r, c), read.rgb.at(k, r, c)) << ext << " " << index;
        }
    EXPECT_EQ(capture.cached_bytes(), manifest.frames.size() * frame_bytes) << ext;
    EXPECT_EQ(uncached.cached_bytes(), 0u) << ext;
    EXPECT_EQ(uncached.frames_read_by_region(), 0u) << ext;  // never decoded whole: nothing refused
  }
}

TEST(CaptureKeptWholeFrames, FramesBeyondTheCacheAreReadByRegionAndGiveTheFilesRows) {
  // A capture whose frames outnumber the cache (a 36 MP tilted capture: 64 frames of 253 MB
  // against the 4 GiB of --max-memory 4) keeps the frames that fit and reads the others by region,
  // the band's strips alone, instead of decoding them whole again for every band.
  TempDir dir;
  Manifest manifest = MakeManifest(kSize, kSize, ".tif");
  for (std::size_t i = 0; i < manifest.frames.size(); ++i) {
    const fs::path path = dir.path() / manifest.frames[i].file;
    fs::create_directories(path.parent_path());
    WriteImageFile(SmoothRgb(kSize, kSize, 0.05f * (i + 1), 0.9f), path, {SampleFormat::kUInt16, PixelEncoding::kLinear});
  }
  WriteManifest(manifest, dir.path());
  ASSERT_GE(manifest.frames.size(), 3u);
  const std::size_t frame_bytes = static_cast<std::size_t>(kSize) * kSize * 7 + 65536 * sizeof(float);
  CaptureOptions room_for_two;
  room_for_two.decode_cache_bytes = 2 * frame_bytes + frame_bytes / 2;
  const Capture capture = Capture::Open(dir.path(), room_for_two);
  CaptureOptions none;
  none.decode_cache_bytes = 0;
  const Capture uncached = Capture::Open(dir.path(), none);
  for (int sweep = 0; sweep < 2; ++sweep)
    for (int band = 0; band < kSize; band += 16)
      for (std::size_t index = 0; index < manifest.frames.size(); ++index) {
        const DecodedFrame part = capture.LoadFrameRows(index, band, 16);
        const DecodedFrame read = uncached.LoadFrameRows(index, band, 16);
        for (int k = 0; k < 3; ++k)
          for (int r = 0; r < 16; ++r)
            for (int c = 0; c < kSize; ++c) ASSERT_EQ(part.rgb.at(k, r, c), read.rgb.at(k, r, c)) << index;
        EXPECT_LE(capture.cached_bytes(), room_for_two.decode_cache_bytes);
      }
  EXPECT_EQ(capture.cached_bytes(), 2 * frame_bytes);
  EXPECT_EQ(capture.frames_read_by_region(), manifest.frames.size() - 2);
}

TEST_F(CaptureFolder, SaturationSurvivesNormalisation) {
  // Overwrite sample 1 with a frame that clips in one photosite.
  Image rgb = FrameContent(1);
  rgb.at(1, 10, 11) = 1.0f;  // green at (10, 11) in RGGB
  DngWriteOptions opt;
  opt.black_level = kBlack;
  opt.white_level = kWhite;
  WriteDng(dir_.path() / manifest_.frames[1].file, MosaicFromLinearRgb(rgb, opt.pattern, kBlack, kWhite), kSize, kSize,
           opt);
  const Capture capture = Capture::Open(dir_.path());
  FrameLoadOptions norm;
  norm.divide_by_exposure = true;
  const DecodedFrame f = capture.LoadFrame(1, norm);
  EXPECT_TRUE(f.IsSaturated(10, 11));
  EXPECT_FALSE(f.IsSaturated(30, 30));
}

TEST_F(CaptureFolder, DecodeOptionsComeFromTheFramesCamera) {
  const Capture capture = Capture::Open(dir_.path());
  const FrameDecodeOptions opt = capture.DecodeOptions(1);
  ASSERT_TRUE(opt.response.has_value());
  EXPECT_EQ(opt.response->white_level, kWhite);
  EXPECT_FALSE(opt.white_balance.has_value());
}

TEST_F(CaptureFolder, ConcurrentRegionReadsAgree) {
  // Two threads sweep row bands of both RAW frames through one shared cache.
  const Capture capture = Capture::Open(dir_.path());
  const DecodedFrame full0 = capture.LoadFrame(0), full1 = capture.LoadFrame(1);
  std::vector<int> mismatches(2, 0);
  std::vector<std::thread> workers;
  for (int t = 0; t < 2; ++t) {
    workers.emplace_back([&, t] {
      for (int band = 0; band < kSize; band += 16) {
        for (std::size_t index : {std::size_t{0}, std::size_t{1}}) {
          const DecodedFrame part = capture.LoadFrameRows(index, band, 16);
          const DecodedFrame& full = index == 0 ? full0 : full1;
          for (int r = 0; r < 16; ++r) mismatches[t] += part.rgb.at(2, r, 40) != full.rgb.at(2, band + r, 40);
        }
      }
    });
  }
  for (auto& w : workers) w.join();
  EXPECT_EQ(mismatches[0] + mismatches[1], 0);
  EXPECT_EQ(capture.cached_bytes(), 2u * kSize * kSize * 7);
}

}  // namespace
}  // namespace u3mscan
