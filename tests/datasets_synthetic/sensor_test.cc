#include "datasets_synthetic/sensor.h"

#include <gtest/gtest.h>

#include <cmath>

namespace u3mscan::synthetic {
namespace {

constexpr int kSize = 64;
constexpr double kLevel = 0.3;
// Mean and spread over 4096 pixels: 5 standard errors of the mean, 10 % on the sigma.
constexpr double kMeanStandardErrors = 5.0;
constexpr double kSigmaRelativeTolerance = 0.1;

TEST(SensorTest, NoiseMeanAndSpreadFollowTheModel) {
  const SensorSpec sensor;
  const Image flat(kSize, kSize, 3, static_cast<float>(kLevel));
  const RawFrame raw = ExposeSensor(flat, sensor, 1, FrameSeed(1, "frames/a.dng"), false);
  const Image decoded = RawToLinear(raw, sensor);
  const double sigma = NoiseSigma(sensor, kLevel);
  for (int c = 0; c < 3; ++c) {
    double sum = 0, sum2 = 0;
    for (float v : decoded.plane(c)) {
      sum += v;
      sum2 += v * v;
    }
    const double n = decoded.pixel_count();
    const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
    EXPECT_NEAR(mean, kLevel, kMeanStandardErrors * sigma / std::sqrt(n));
    EXPECT_NEAR(sd, sigma, kSigmaRelativeTolerance * sigma);
  }
}

// Without noise a frame is the expected DN, rounded: every pixel of a flat frame decodes to the
// level within half a DN, the same under any seed, and NoiseSigma says so (quantisation only).
TEST(SensorTest, WithoutNoiseAFrameIsTheExpectedLevelRounded) {
  SensorSpec sensor;
  sensor.noise = false;
  const double half_dn = 0.5 / (sensor.white_level_dn - sensor.black_level_dn);
  const Image flat(kSize, kSize, 3, static_cast<float>(kLevel));
  const RawFrame a = ExposeSensor(flat, sensor, 1, FrameSeed(1, "frames/a.dng"), false);
  const RawFrame b = ExposeSensor(flat, sensor, 2, FrameSeed(9, "frames/b.dng"), true);
  for (const RawFrame* raw : {&a, &b}) {
    const Image decoded = RawToLinear(*raw, sensor);
    for (float v : decoded.data()) ASSERT_NEAR(v, kLevel, half_dn);
  }
  EXPECT_LT(NoiseSigma(sensor, kLevel), half_dn);
  sensor.noise = true;
  EXPECT_GT(NoiseSigma(sensor, kLevel), 10.0 * half_dn) << "the noise the flag takes away";
}

TEST(SensorTest, SameSeedSameFrameOtherSeedOtherNoise) {
  const SensorSpec sensor;
  const Image flat(kSize, kSize, 3, 0.2f);
  const RawFrame a = ExposeSensor(flat, sensor, 1, FrameSeed(7, "x"), true);
  const RawFrame b = ExposeSensor(flat, sensor, 1, FrameSeed(7, "x"), true);
  const RawFrame c = ExposeSensor(flat, sensor, 1, FrameSeed(8, "x"), true);
  const RawFrame d = ExposeSensor(flat, sensor, 1, FrameSeed(7, "y"), true);
  EXPECT_EQ(a.dn, b.dn);
  EXPECT_NE(a.dn, c.dn);
  EXPECT_NE(a.dn, d.dn);
}

TEST(SensorTest, BayerMosaicSamplesRggb) {
  SensorSpec sensor;
  sensor.read_noise_e = 0;
  sensor.fixed_pattern_dn = 0;
  sensor.full_well_e = 1e12;  // no shot noise to speak of
  Image colour(4, 4, 3);
  for (int c = 0; c < 3; ++c)
    for (float& v : colour.plane(c)) v = 0.1f * (c + 1);
  const Image decoded = RawToLinear(ExposeSensor(colour, sensor, 1, 1, true), sensor);
  ASSERT_EQ(decoded.channels(), 1);
  const double step = 1.0 / (sensor.white_level_dn - sensor.black_level_dn);
  EXPECT_NEAR(decoded.at(0, 0, 0), 0.1, step);  // R
  EXPECT_NEAR(decoded.at(0, 0, 1), 0.2, step);  // G
  EXPECT_NEAR(decoded.at(0, 1, 0), 0.2, step);  // G
  EXPECT_NEAR(decoded.at(0, 1, 1), 0.3, step);  // B
}

TEST(SensorTest, ClipsAtWhiteLevel) {
  const SensorSpec sensor;
  const Image bright(8, 8, 3, 3.0f);
  const RawFrame raw = ExposeSensor(bright, sensor, 1, 1, false);
  for (auto dn : raw.dn) EXPECT_EQ(dn, static_cast<std::uint16_t>(sensor.white_level_dn));
}

}  // namespace
}  // namespace u3mscan::synthetic
