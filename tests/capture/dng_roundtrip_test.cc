// WriteDng -> libraw (through DecodeFrame) gives back the linear RGB the mosaic was made from:
// the contract between the synthetic scanner and the RAW path of the frame decoder.

#include <gtest/gtest.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>

#include "capture/dng_writer.h"
#include "capture/frame_decoder.h"
#include "capture_test_util.h"
#include "core/error.h"

namespace u3mscan {
namespace {

using testing::SmoothRgb;
using testing::TempDir;

constexpr std::uint16_t kBlack = 512;
constexpr std::uint16_t kWhite = 16383;  // a 14-bit sensor
// One raw step in linear units, and libraw's 16-bit output step.
constexpr double kRawStep = 1.0 / (kWhite - kBlack);
constexpr double kOutputStep = 1.0 / 65535.0;
// A flat field has no demosaicing error: quantisation only.
constexpr double kFlatTolerance = kRawStep / 2 + kOutputStep;
// AHD on the slow sinusoids of SmoothRgb (gradients <= 0.015 per pixel): measured ~2e-3.
constexpr double kSmoothTolerance = 5e-3;
// Demosaicing has no full neighbourhood at the border.
constexpr int kBorder = 3;

double MaxInteriorError(const Image& decoded, const Image& truth, int border) {
  double worst = 0.0;
  for (int k = 0; k < 3; ++k) {
    for (int r = border; r < truth.height() - border; ++r) {
      for (int c = border; c < truth.width() - border; ++c) {
        worst = std::max(worst, std::abs(double(decoded.at(k, r, c)) - truth.at(k, r, c)));
      }
    }
  }
  return worst;
}

Image Flat(int w, int h, const std::array<float, 3>& rgb) {
  Image img(w, h, 3);
  for (int k = 0; k < 3; ++k) std::fill(img.plane(k).begin(), img.plane(k).end(), rgb[k]);
  return img;
}

DngWriteOptions Levels(CfaPattern pattern = CfaPattern::kRggb) {
  DngWriteOptions opt;
  opt.pattern = pattern;
  opt.black_level = kBlack;
  opt.white_level = kWhite;
  return opt;
}

TEST(DngRoundTrip, CfaColourAtFollowsThePatternName) {
  EXPECT_EQ(CfaColourAt(CfaPattern::kRggb, 0, 0), 0);
  EXPECT_EQ(CfaColourAt(CfaPattern::kRggb, 1, 1), 2);
  EXPECT_EQ(CfaColourAt(CfaPattern::kBggr, 0, 0), 2);
  EXPECT_EQ(CfaColourAt(CfaPattern::kGrbg, 0, 1), 0);
  EXPECT_EQ(CfaColourAt(CfaPattern::kGbrg, 1, 0), 0);
  EXPECT_EQ(CfaColourAt(CfaPattern::kGbrg, 2, 3), 2);  // repeats every 2
}

TEST(DngRoundTrip, FlatFieldDecodesExactlyForEveryPattern) {
  TempDir dir;
  const std::array<float, 3> rgb{0.7f, 0.3f, 0.1f};
  const Image truth = Flat(32, 32, rgb);
  for (CfaPattern pattern : {CfaPattern::kRggb, CfaPattern::kBggr, CfaPattern::kGrbg, CfaPattern::kGbrg}) {
    const auto opt = Levels(pattern);
    const auto path = dir.path() / "flat.dng";
    WriteDng(path, MosaicFromLinearRgb(truth, pattern, kBlack, kWhite), 32, 32, opt);
    const DecodedFrame f = DecodeFrame(path);
    ASSERT_EQ(f.rgb.width(), 32);
    ASSERT_EQ(f.rgb.height(), 32);
    EXPECT_EQ(f.encoding, FrameEncoding::kRaw);
    EXPECT_LE(MaxInteriorError(f.rgb, truth, 0), kFlatTolerance) << "pattern " << int(pattern);
    EXPECT_TRUE(std::none_of(f.saturated.begin(), f.saturated.end(), [](auto s) { return s != 0; }));
  }
}

TEST(DngRoundTrip, SmoothImageDecodesWithinDemosaicingError) {
  TempDir dir;
  const Image truth = SmoothRgb(64, 64);
  for (CfaPattern pattern : {CfaPattern::kRggb, CfaPattern::kBggr, CfaPattern::kGrbg, CfaPattern::kGbrg}) {
    const auto path = dir.path() / "smooth.dng";
    WriteDng(path, MosaicFromLinearRgb(truth, pattern, kBlack, kWhite), 64, 64, Levels(pattern));
    const DecodedFrame f = DecodeFrame(path);
    EXPECT_LE(MaxInteriorError(f.rgb, truth, kBorder), kSmoothTolerance) << "pattern " << int(pattern);
  }
}

TEST(DngRoundTrip, AsShotNeutralIsUndoneRelativeToTheSmallestMultiplier) {
  // A camera whose red photosites see half as much of a white light: AsShotNeutral (0.5, 1, 0.8)
  // multiplies red by 2 and blue by 1.25; green (multiplier 1) keeps 1.0 = white level.
  TempDir dir;
  const Image truth = Flat(32, 32, {0.35f, 0.3f, 0.4f});
  auto opt = Levels();
  opt.as_shot_neutral = {0.5, 1.0, 0.8};
  const auto path = dir.path() / "wb.dng";
  WriteDng(path, MosaicFromLinearRgb(truth, opt.pattern, kBlack, kWhite), 32, 32, opt);
  const DecodedFrame f = DecodeFrame(path);
  EXPECT_NEAR(f.rgb.at(0, 16, 16), 0.70, 2 * kFlatTolerance);
  EXPECT_NEAR(f.rgb.at(1, 16, 16), 0.30, 2 * kFlatTolerance);  // libraw quantises at 1/2 scale
  EXPECT_NEAR(f.rgb.at(2, 16, 16), 0.50, 2 * kFlatTolerance);

  // The manifest may override: unit multipliers give the raw sensor colour back.
  FrameDecodeOptions raw_colour;
  raw_colour.white_balance = std::array<double, 3>{1.0, 1.0, 1.0};
  const DecodedFrame g = DecodeFrame(path, raw_colour);
  EXPECT_NEAR(g.rgb.at(0, 16, 16), 0.35, kFlatTolerance);
  EXPECT_NEAR(g.rgb.at(2, 16, 16), 0.40, kFlatTolerance);
}

TEST(DngRoundTrip, SaturatedPhotositesAreFlaggedWithTheirDemosaicingNeighbourhood) {
  TempDir dir;
  Image truth = Flat(48, 48, {0.5f, 0.5f, 0.5f});
  truth.at(0, 20, 20) = 1.0f;  // one red photosite (RGGB: even row, even col) at white level
  const auto path = dir.path() / "sat.dng";
  WriteDng(path, MosaicFromLinearRgb(truth, CfaPattern::kRggb, kBlack, kWhite), 48, 48, Levels());
  const DecodedFrame f = DecodeFrame(path);
  EXPECT_TRUE(f.IsSaturated(20, 20));
  EXPECT_TRUE(f.IsSaturated(22, 18));   // within the 2-pixel demosaicing radius
  EXPECT_FALSE(f.IsSaturated(20, 23));  // beyond it
  EXPECT_FALSE(f.IsSaturated(5, 5));
  const long flagged = std::count(f.saturated.begin(), f.saturated.end(), std::uint8_t{1});
  EXPECT_EQ(flagged, 25);  // the 5x5 neighbourhood

  // A manifest response with a lower white level turns the whole (0.5) frame saturated.
  FrameDecodeOptions low_white;
  low_white.response = SensorResponse{kBlack, kBlack + 0.4 * (kWhite - kBlack)};
  const DecodedFrame g = DecodeFrame(path, low_white);
  EXPECT_TRUE(std::all_of(g.saturated.begin(), g.saturated.end(), [](auto s) { return s != 0; }));
}

TEST(DngRoundTrip, ResponseLevelsOverrideTheFileLevels) {
  // The manifest says the black level is 1000 ADU and white 9000, the file says 512/16383.
  TempDir dir;
  const Image truth = Flat(32, 32, {0.5f, 0.5f, 0.5f});
  const auto path = dir.path() / "levels.dng";
  WriteDng(path, MosaicFromLinearRgb(truth, CfaPattern::kRggb, kBlack, kWhite), 32, 32, Levels());
  FrameDecodeOptions opt;
  opt.response = SensorResponse{1000.0, 9000.0};
  const DecodedFrame f = DecodeFrame(path, opt);
  const double raw = kBlack + 0.5 * (kWhite - kBlack);
  EXPECT_NEAR(f.rgb.at(1, 16, 16), (raw - 1000.0) / 8000.0, 1.0 / 8000.0);
}

TEST(DngRoundTrip, ColourMatrixIsAppliedAsLibrawDoes) {
  // A camera whose channels mix the sRGB primaries: camera = M * linear sRGB (rows sum to 1, so
  // white stays white). ColorMatrix1 = M * inverse(sRGB->XYZ); libraw inverts it back, so the
  // decoded frame is the original linear sRGB. (libraw 0.20 ignores a matrix whose camera->sRGB
  // [0][0] is below 0.125, e.g. a channel permutation; real cameras are far from that.)
  TempDir dir;
  const Eigen::Vector3d srgb(0.6, 0.3, 0.15);
  Eigen::Matrix3d mix;
  mix << 0.80, 0.15, 0.05,  //
      0.10, 0.80, 0.10,     //
      0.05, 0.15, 0.80;
  const Eigen::Vector3d camera = mix * srgb;
  auto opt = Levels();
  opt.colour_matrix = mix * LinearSrgbToXyz().inverse();
  const Image camera_rgb = Flat(32, 32, {float(camera[0]), float(camera[1]), float(camera[2])});
  const auto path = dir.path() / "matrix.dng";
  WriteDng(path, MosaicFromLinearRgb(camera_rgb, opt.pattern, kBlack, kWhite), 32, 32, opt);
  const DecodedFrame f = DecodeFrame(path);
  // Colour-matrix coefficients go through SRATIONAL and a float inverse: a few output steps.
  constexpr double kMatrixTolerance = 5e-4;
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(f.rgb.at(k, 16, 16), srgb[k], kMatrixTolerance) << k;
  // Without the matrix the same mosaic decodes to the camera values: the matrix was applied.
  WriteDng(path, MosaicFromLinearRgb(camera_rgb, opt.pattern, kBlack, kWhite), 32, 32, Levels());
  EXPECT_NEAR(DecodeFrame(path).rgb.at(0, 16, 16), camera[0], kFlatTolerance);
}

TEST(DngRoundTrip, OutputClippedByTheColourMatrixIsFlagged) {
  // Camera values below white whose sRGB red exceeds the white level: libraw's 16-bit output
  // clips it, so the pixel is no longer data although no photosite saturated.
  TempDir dir;
  Eigen::Matrix3d mix;
  mix << 0.80, 0.15, 0.05,  //
      0.10, 0.80, 0.10,     //
      0.05, 0.15, 0.80;
  auto opt = Levels();
  opt.colour_matrix = mix * LinearSrgbToXyz().inverse();
  const Eigen::Vector3d camera(0.95, 0.3, 0.3);
  ASSERT_GT((mix.inverse() * camera)[0], 1.05);  // the premise: red beyond white after the matrix
  const auto path = dir.path() / "clip.dng";
  WriteDng(path, MosaicFromLinearRgb(Flat(32, 32, {0.95f, 0.3f, 0.3f}), opt.pattern, kBlack, kWhite), 32, 32, opt);
  const DecodedFrame f = DecodeFrame(path);
  EXPECT_TRUE(f.IsSaturated(16, 16));
  // The same values without the matrix stay data.
  WriteDng(path, MosaicFromLinearRgb(Flat(32, 32, {0.95f, 0.3f, 0.3f}), opt.pattern, kBlack, kWhite), 32, 32, Levels());
  EXPECT_FALSE(DecodeFrame(path).IsSaturated(16, 16));
}

TEST(DngRoundTrip, RejectsBadArguments) {
  TempDir dir;
  std::vector<std::uint16_t> mosaic(32 * 32, 0);
  EXPECT_THROW(WriteDng(dir.path() / "a.dng", mosaic, 32, 31), std::invalid_argument);
  std::vector<std::uint16_t> tiny(8 * 8, 0);
  EXPECT_THROW(WriteDng(dir.path() / "b.dng", tiny, 8, 8), std::invalid_argument);
  DngWriteOptions opt;
  opt.black_level = 100;
  opt.white_level = 100;
  EXPECT_THROW(WriteDng(dir.path() / "c.dng", mosaic, 32, 32, opt), std::invalid_argument);
  EXPECT_THROW(WriteDng(dir.path() / "no/such/dir/d.dng", mosaic, 32, 32), InputError);
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "a.dng"));
}

}  // namespace
}  // namespace u3mscan
