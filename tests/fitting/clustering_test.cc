#include "fitting/clustering.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

namespace u3mscan::fitting {
namespace {

// Spread of the synthetic groups in feature units: well inside min_separation's scale.
constexpr float kGroupSpread = 0.02f;

std::vector<float> Groups(const std::vector<std::vector<float>>& centres, int per_group, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.0f, kGroupSpread);
  std::vector<float> out;
  for (int i = 0; i < per_group; ++i) {
    for (const auto& c : centres) {  // interleaved, so that groups are not contiguous
      for (float v : c) out.push_back(v + noise(rng));
    }
  }
  return out;
}

TEST(Clustering, SeparatesDistinctAppearancesDeterministically) {
  const std::vector<std::vector<float>> centres = {{-1.5f, 1.6f, 1.7f, -0.2f, 0.1f, 0.2f, 0.3f},
                                                   {-1.0f, 3.0f, 1.2f, -0.1f, 0.5f, 1.0f, 2.0f},
                                                   {-2.5f, 1.6f, 1.7f, -0.3f, 0.05f, 0.1f, 0.1f}};
  const int per_group = 50;
  const std::vector<float> features = Groups(centres, per_group, 5);
  std::vector<std::uint8_t> valid(features.size() / kAppearanceFeatureCount, 1);
  valid[4] = 0;
  ClusteringOptions options;
  options.cluster_count = 6;
  const Clustering a = ClusterPixels(features, kAppearanceFeatureCount, valid, options);
  const Clustering b = ClusterPixels(features, kAppearanceFeatureCount, valid, options);
  EXPECT_EQ(a.labels, b.labels);
  EXPECT_EQ(a.cluster_count, 3) << "seeding stops once every pixel is near a centre";
  EXPECT_EQ(a.labels[4], -1);
  // Pixel i belongs to group i % 3: same group <=> same label.
  for (std::size_t i = 0; i < valid.size(); ++i) {
    if (!valid[i]) continue;
    EXPECT_EQ(a.labels[i], a.labels[i % 3]) << i;
    EXPECT_EQ(NearestCluster(a, &features[i * kAppearanceFeatureCount], kAppearanceFeatureCount, options), a.labels[i]);
  }
  EXPECT_NE(a.labels[0], a.labels[1]);
  EXPECT_NE(a.labels[1], a.labels[2]);
  EXPECT_NE(a.labels[0], a.labels[2]);
}

TEST(Clustering, UniformAppearanceIsOneCluster) {
  const std::vector<float> features = Groups({{-1.0f, 1.5f, 1.8f, -0.1f, 0.2f, 0.3f, 0.5f}}, 200, 9);
  std::vector<std::uint8_t> valid(200, 1);
  ClusteringOptions options;
  const Clustering c = ClusterPixels(features, kAppearanceFeatureCount, valid, options);
  EXPECT_EQ(c.cluster_count, 1);
  ASSERT_EQ(c.sizes.size(), 1u);
  EXPECT_EQ(c.sizes[0], 200);
}

TEST(Clustering, FeaturesIgnoreWhichLightMadeTheHighlight) {
  // The same ratios in another order (another normal, another light on the highlight) give the
  // same features.
  const float albedo[3] = {0.5f, 0.3f, 0.2f};
  std::vector<float> ratios = {0.2f, 0.21f, 0.19f, 0.8f, 0.22f, 0.2f, 0.18f, 0.2f};
  std::vector<float> shuffled = {0.8f, 0.2f, 0.2f, 0.18f, 0.22f, 0.19f, 0.21f, 0.2f};
  float fa[kAppearanceFeatureCount], fb[kAppearanceFeatureCount];
  AppearanceFeatures(albedo, ratios, fa);
  AppearanceFeatures(albedo, shuffled, fb);
  for (int i = 0; i < kAppearanceFeatureCount; ++i) EXPECT_FLOAT_EQ(fa[i], fb[i]);
  EXPECT_GT(fa[6], 1.0f) << "the highlight shows in the upper tail (log 4)";
}

TEST(Clustering, RejectsMismatchedInput) {
  std::vector<float> features(10);
  std::vector<std::uint8_t> valid(3, 1);
  EXPECT_THROW(ClusterPixels(features, kAppearanceFeatureCount, valid, ClusteringOptions()), std::invalid_argument);
}

}  // namespace
}  // namespace u3mscan::fitting
