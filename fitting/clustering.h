#pragma once
// Clustering: pixels grouped by appearance so that the weakly constrained Principled parameters
// (specular, tints, sheen) are shared by many similar pixels. Deterministic k-means (k-means++
// seeding from a fixed seed) on a small feature vector per pixel:
//   - base colour: log luminance and chromaticity (r, g) of the albedo,
//   - gloss profile: quantiles of the pixel's observed reflectance ratio over all its observations,
//     each divided by the pixel's median ratio. A ratio is rgb luminance / (cos_l * E): a matte
//     pixel has a flat profile, a glossy one a long upper tail. Quantiles do not depend on which
//     light hits the highlight, so pixels of one material but different normals stay together.

#include <cstdint>
#include <span>
#include <vector>

namespace u3mscan::fitting {

// Number of features AppearanceFeatures writes.
inline constexpr int kAppearanceFeatureCount = 7;

struct ClusteringOptions {
  int cluster_count = 8;      // k; fewer clusters come out when fewer distinct pixels exist
  int max_samples = 20000;    // k-means runs on at most this many pixels (evenly strided)
  int iterations = 30;        // Lloyd iterations (stops earlier when no label changes)
  std::uint64_t seed = 1;     // k-means++ seeding
  double color_weight = 1.0;  // multiplies the 3 colour features
  double gloss_weight = 1.0;  // multiplies the 4 gloss-profile features
  // Seeding stops once every pixel is closer than this to a centre (feature units, see
  // AppearanceFeatures): a uniform sample becomes one cluster instead of k arbitrary slices.
  double min_separation = 0.3;

  bool Check() const;
};

// Features of one pixel. albedo_rgb: linear RGB (any positive scale); ratios: the observed
// reflectance ratio of each usable observation (modified: partially sorted in place).
// Units: natural log of luminance; chromaticity r, g times 5 (a 0.03 shift of chromaticity weighs
// like a 15 % change of luminance); natural log of quantile / median for the profile.
void AppearanceFeatures(const float albedo_rgb[3], std::span<float> ratios, float* features);

struct Clustering {
  int cluster_count = 0;
  std::vector<int> labels;                // per pixel, -1 for invalid pixels; 0..cluster_count-1
  std::vector<std::int64_t> sizes;        // pixels per cluster
  std::vector<float> centroids;           // cluster_count x dims, weighted feature units
};

// k-means over `features` (pixel_count x dims, row-major). Pixels with valid[i] == 0 get label -1.
// Deterministic for a given seed and input. Empty clusters are removed and labels renumbered so
// that clusters are ordered by their first pixel.
Clustering ClusterPixels(std::span<const float> features, int dims, std::span<const std::uint8_t> valid,
                         const ClusteringOptions& options);

// Label of the nearest centre for one pixel's (unweighted) features, as ClusterPixels assigns it.
// For labelling pixels that were not in the clustered set; cheap enough to call per pixel.
int NearestCluster(const Clustering& clustering, const float* features, int dims, const ClusteringOptions& options);

}  // namespace u3mscan::fitting
