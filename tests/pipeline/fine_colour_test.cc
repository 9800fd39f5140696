// The base colour averaged from the fine grid onto the maps' grid (pipeline/fine_colour.h).
#include "pipeline/fine_colour.h"

#include <gtest/gtest.h>

#include <limits>
#include <stdexcept>

namespace u3mscan {
namespace {

constexpr int kFactor = 2;
constexpr float kExact = 1e-6f;  // float sums of a few values in [0, 1]

// A fine fit of `maps_w` x `maps_h` map pixels at kFactor: colour (r, g, b) = (row, col, 1) / 16
// in fine pixels, every pixel fitted (cluster 0).
struct FineFit {
  Image base_color, cluster_id;
  FineFit(int maps_w, int maps_h)
      : base_color(maps_w * kFactor, maps_h * kFactor, 3, 0.0f), cluster_id(maps_w * kFactor, maps_h * kFactor, 1, 0.0f) {
    for (int r = 0; r < base_color.height(); ++r) {
      for (int c = 0; c < base_color.width(); ++c) {
        base_color.at(0, r, c) = r / 16.0f;
        base_color.at(1, r, c) = c / 16.0f;
        base_color.at(2, r, c) = 1.0f / 16.0f;
      }
    }
  }
};

TEST(FineColourAverage, EachMapPixelGetsTheMeanOfItsFinePixels) {
  const FineFit fine(3, 2);
  FineColourAverage average(3, 2, kFactor);
  average.Add(fine.base_color, fine.cluster_id, 0);
  Image maps(3, 2, 3, 0.5f);
  const Image maps_clusters(3, 2, 1, 0.0f);
  EXPECT_EQ(average.ApplyTo(maps_clusters, &maps), 6);
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 3; ++c) {
      // Fine rows 2r and 2r + 1: mean (2r + 0.5) / 16; the same for the columns.
      EXPECT_NEAR(maps.at(0, r, c), (2 * r + 0.5f) / 16.0f, kExact) << r << "," << c;
      EXPECT_NEAR(maps.at(1, r, c), (2 * c + 0.5f) / 16.0f, kExact) << r << "," << c;
      EXPECT_NEAR(maps.at(2, r, c), 1.0f / 16.0f, kExact);
    }
  }
}

TEST(FineColourAverage, UnfittedFinePixelsAndMapPixelsAreLeftOut) {
  FineFit fine(2, 1);
  // Map pixel (0, 0): fine (0, 0) unfitted, fine (1, 1) not finite: the mean of (0, 1) and (1, 0).
  fine.cluster_id.at(0, 0, 0) = -1.0f;
  fine.base_color.at(2, 1, 1) = std::numeric_limits<float>::quiet_NaN();
  FineColourAverage average(2, 1, kFactor);
  average.Add(fine.base_color, fine.cluster_id, 0);
  Image maps(2, 1, 3, 0.5f);
  Image maps_clusters(2, 1, 1, 0.0f);
  maps_clusters.at(0, 0, 1) = -1.0f;  // map pixel (0, 1) was not fitted on the maps' grid: kept
  EXPECT_EQ(average.ApplyTo(maps_clusters, &maps), 1);
  EXPECT_NEAR(maps.at(0, 0, 0), (0.0f + 1.0f) / 2.0f / 16.0f, kExact);  // rows 0 and 1
  EXPECT_NEAR(maps.at(1, 0, 0), (1.0f + 0.0f) / 2.0f / 16.0f, kExact);  // columns 1 and 0
  for (int ch = 0; ch < 3; ++ch) EXPECT_EQ(maps.at(ch, 0, 1), 0.5f);

  // A map pixel none of whose fine pixels was fitted keeps its colour.
  Image none(2, 2, 1, -1.0f);
  FineColourAverage empty(1, 1, kFactor);
  empty.Add(Image(2, 2, 3, 0.9f), none, 0);
  Image one(1, 1, 3, 0.25f);
  EXPECT_EQ(empty.ApplyTo(Image(1, 1, 1, 0.0f), &one), 0);
  EXPECT_EQ(one.at(0, 0, 0), 0.25f);
}

TEST(FineColourAverage, BandsGiveTheWholeGridsMeans) {
  // Bands of 3 fine rows: a band boundary falls inside map row 1 (fine rows 2 and 3).
  const FineFit fine(2, 3);
  FineColourAverage whole(2, 3, kFactor), banded(2, 3, kFactor);
  whole.Add(fine.base_color, fine.cluster_id, 0);
  for (int row0 = 0; row0 < 6; row0 += 3) {
    Image colour(4, 3, 3, 0.0f), clusters(4, 3, 1, 0.0f);
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) {
        for (int ch = 0; ch < 3; ++ch) colour.at(ch, r, c) = fine.base_color.at(ch, row0 + r, c);
      }
    }
    banded.Add(colour, clusters, row0);
  }
  Image a(2, 3, 3, 0.0f), b(2, 3, 3, 0.0f);
  const Image clusters(2, 3, 1, 0.0f);
  ASSERT_EQ(whole.ApplyTo(clusters, &a), 6);
  ASSERT_EQ(banded.ApplyTo(clusters, &b), 6);
  for (int ch = 0; ch < 3; ++ch) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 2; ++c) EXPECT_NEAR(a.at(ch, r, c), b.at(ch, r, c), kExact);
    }
  }
  EXPECT_NEAR(b.at(0, 1, 0), 2.5f / 16.0f, kExact);
}

TEST(FineColourAverage, WeightsMakeTheMeanAWeightedOne) {
  // Map pixel (0, 0) of fine rows 0-1, columns 0-1: red = row / 16, weights 3 on row 0 and 1 on row 1
  // give (3 * 0 + 1 * 1) / 4 / 16 for a plain mean's 0.5 / 16; a weight of 0 leaves a pixel out.
  const FineFit fine(1, 1);
  Image weights(2, 2, 1, 3.0f);
  weights.at(0, 1, 0) = weights.at(0, 1, 1) = 1.0f;
  FineColourAverage average(1, 1, kFactor);
  average.Add(fine.base_color, fine.cluster_id, 0, weights);
  Image maps(1, 1, 3, 0.5f);
  ASSERT_EQ(average.ApplyTo(Image(1, 1, 1, 0.0f), &maps), 1);
  EXPECT_NEAR(maps.at(0, 0, 0), 0.25f / 16.0f, kExact);
  EXPECT_NEAR(maps.at(1, 0, 0), 0.5f / 16.0f, kExact);  // columns 0 and 1, equal weight within each row

  weights.at(0, 0, 0) = weights.at(0, 0, 1) = 0.0f;  // only row 1 counts
  FineColourAverage row_one(1, 1, kFactor);
  row_one.Add(fine.base_color, fine.cluster_id, 0, weights);
  ASSERT_EQ(row_one.ApplyTo(Image(1, 1, 1, 0.0f), &maps), 1);
  EXPECT_NEAR(maps.at(0, 0, 0), 1.0f / 16.0f, kExact);
  EXPECT_THROW(row_one.Add(fine.base_color, fine.cluster_id, 0, Image(2, 1, 1, 1.0f)), std::invalid_argument);
}

TEST(FineColourAverage, RowsOffTheFineGridAreRefused) {
  FineColourAverage average(2, 2, kFactor);
  EXPECT_THROW(average.Add(Image(4, 2, 3, 0.0f), Image(4, 2, 1, 0.0f), 3), std::invalid_argument);  // rows 3-4 of 4
  EXPECT_THROW(average.Add(Image(3, 2, 3, 0.0f), Image(3, 2, 1, 0.0f), 0), std::invalid_argument);  // 3 wide, not 4
  EXPECT_THROW(average.Add(Image(4, 2, 1, 0.0f), Image(4, 2, 1, 0.0f), 0), std::invalid_argument);  // 1 channel
  Image wrong(3, 2, 3, 0.0f);
  EXPECT_THROW(average.ApplyTo(Image(2, 2, 1, 0.0f), &wrong), std::invalid_argument);
  EXPECT_THROW(FineColourAverage(2, 2, 0), std::invalid_argument);
}

}  // namespace
}  // namespace u3mscan
