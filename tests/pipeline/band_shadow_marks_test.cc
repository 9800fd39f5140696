// BandShadowMarks (pipeline/band_shadow_marks.h): marks kept from one build of a band and put on
// another must be the flags MarkCastShadows set on the first, whatever else the flags hold.
#include "pipeline/band_shadow_marks.h"

#include <gtest/gtest.h>

#include <stdexcept>

#include "core/image.h"
#include "reconstruction/cast_shadows.h"

namespace u3mscan {
namespace {

// A band of `rows` x 12 pixels, two lights at 30 deg elevation from +x and -y and one overhead,
// observed by one view each (the first twice, as a second view would).
Stack Band(int rows, int row0) {
  Stack s;
  s.grid.width = 12;
  s.grid.height = rows;
  s.grid.pitch_mm = 0.1;
  s.grid.x0_mm = 0.0;
  s.grid.y1_mm = -row0 * 0.1;
  for (const Eigen::Vector3d& d : {Eigen::Vector3d(0.866, 0, 0.5), Eigen::Vector3d(0, -0.866, 0.5), Eigen::Vector3d(0, 0, 1)}) {
    LightModel l;
    l.direction_in_world = d.normalized();
    s.lights.push_back(l);
  }
  for (int light : {0, 1, 2, 0}) {
    Observation o;
    o.light = light;
    o.rgb = Image(s.grid.width, rows, 3, 0.5f, s.grid.pitch_mm);
    s.observations.push_back(std::move(o));
  }
  return s;
}

TEST(BandShadowMarks, KeptMarksPutOnAnotherBuildAreTheMarchedOnes) {
  // A wall 0.3 mm high across columns 6-7 of a 12 x 12 grid: it shadows its -x side from light 0.
  constexpr int kRows = 12, kBandRows = 5, kRow0 = 4;
  MetricGrid whole;
  whole.width = 12;
  whole.height = kRows;
  whole.pitch_mm = 0.1;
  Image height(12, kRows, 1, 0.0f, 0.1);
  for (int r = 0; r < kRows; ++r) height.at(0, r, 6) = height.at(0, r, 7) = 0.3f;
  reconstruction::CastShadowOptions options;
  Stack marched = Band(kBandRows, kRow0);
  const reconstruction::CastShadowCounts counts = reconstruction::MarkCastShadows(height, whole, &marched, options);
  ASSERT_GT(counts.marked, 0);
  BandShadowMarks marks(whole.width, whole.height, 3);
  marks.Keep(marched, kRow0);

  Stack again = Band(kBandRows, kRow0);
  // Flags of other kinds stay; a stale cast-shadow flag goes.
  again.observations[1].flags.assign(12 * kBandRows, 0);
  again.observations[1].flags[3] = kSaturated | kCastShadow;
  marched.observations[1].flags[3] |= kSaturated;
  marks.Apply(kRow0, &again);
  for (std::size_t k = 0; k < marched.observations.size(); ++k) {
    ASSERT_EQ(again.observations[k].flags.size(), marched.observations[k].flags.size()) << k;
    for (std::size_t i = 0; i < marched.observations[k].flags.size(); ++i) {
      EXPECT_EQ(again.observations[k].flags[i], marched.observations[k].flags[i]) << "observation " << k << " pixel " << i;
    }
  }
}

TEST(BandShadowMarks, ABandOffTheKeptGridIsRefused) {
  BandShadowMarks marks(12, 8, 3);
  Stack band = Band(5, 4);
  EXPECT_THROW(marks.Keep(band, 4), std::invalid_argument);  // rows 4-8 of 8
  EXPECT_THROW(BandShadowMarks(12, 8, 2).Apply(0, &band), std::invalid_argument);  // 3 lights
  EXPECT_NO_THROW(marks.Keep(band, 3));
}

}  // namespace
}  // namespace u3mscan
