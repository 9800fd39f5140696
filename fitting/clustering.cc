#include "fitting/clustering.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>

#include "core/parallel.h"

namespace u3mscan::fitting {
namespace {

// Chromaticity scale of the colour features (see AppearanceFeatures in the header).
constexpr float kChromaScale = 5.0f;
// Floors of logarithms: luminance and reflectance ratios this small are black / no signal.
constexpr float kMinLuminance = 1e-4f;
constexpr float kMinRatio = 1e-6f;
// Quantiles of the ratio profile (the median is the reference they are divided by).
constexpr double kProfileQuantiles[4] = {0.1, 0.75, 0.9, 1.0};

float Quantile(std::span<float> values, double q) {
  const std::size_t k = static_cast<std::size_t>(std::lround(q * (values.size() - 1)));
  std::nth_element(values.begin(), values.begin() + k, values.end());
  return values[k];
}

// Uniform double in [0, 1) from a 64-bit engine, identical on every standard library (the
// std distributions are not specified bit for bit).
double Uniform01(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

float SquaredDistance(const float* a, const float* b, int dims) {
  float d = 0.0f;
  for (int i = 0; i < dims; ++i) {
    const float t = a[i] - b[i];
    d += t * t;
  }
  return d;
}

int Nearest(const float* x, const std::vector<float>& centroids, int k, int dims, float* best_distance) {
  int best = 0;
  float best_d = std::numeric_limits<float>::max();
  for (int c = 0; c < k; ++c) {
    const float d = SquaredDistance(x, &centroids[static_cast<std::size_t>(c) * dims], dims);
    if (d < best_d) {
      best_d = d;
      best = c;
    }
  }
  if (best_distance != nullptr) *best_distance = best_d;
  return best;
}

void FeatureWeights(int dims, const ClusteringOptions& options, float* weights) {
  for (int i = 0; i < dims; ++i) weights[i] = 1.0f;
  if (dims == kAppearanceFeatureCount) {
    for (int i = 0; i < 3; ++i) weights[i] = static_cast<float>(options.color_weight);
    for (int i = 3; i < dims; ++i) weights[i] = static_cast<float>(options.gloss_weight);
  }
}

}  // namespace

bool ClusteringOptions::Check() const {
  return cluster_count >= 1 && max_samples >= 1 && iterations >= 0 && color_weight >= 0.0 && gloss_weight >= 0.0 &&
         min_separation >= 0.0;
}

void AppearanceFeatures(const float albedo_rgb[3], std::span<float> ratios, float* features) {
  const float r = std::max(0.0f, albedo_rgb[0]);
  const float g = std::max(0.0f, albedo_rgb[1]);
  const float b = std::max(0.0f, albedo_rgb[2]);
  const float lum = 0.3f * r + 0.6f * g + 0.1f * b;
  const float sum = r + g + b;
  features[0] = std::log(std::max(lum, kMinLuminance));
  features[1] = sum > 0.0f ? kChromaScale * r / sum : kChromaScale / 3.0f;
  features[2] = sum > 0.0f ? kChromaScale * g / sum : kChromaScale / 3.0f;
  if (ratios.empty()) {
    for (int i = 0; i < 4; ++i) features[3 + i] = 0.0f;
    return;
  }
  const float median = std::max(Quantile(ratios, 0.5), kMinRatio);
  for (int i = 0; i < 4; ++i) {
    features[3 + i] = std::log(std::max(Quantile(ratios, kProfileQuantiles[i]), kMinRatio) / median);
  }
}

Clustering ClusterPixels(std::span<const float> features, int dims, std::span<const std::uint8_t> valid,
                         const ClusteringOptions& options) {
  if (!options.Check()) throw std::invalid_argument("ClusterPixels: invalid ClusteringOptions");
  if (dims <= 0 || features.size() != valid.size() * static_cast<std::size_t>(dims)) {
    throw std::invalid_argument("ClusterPixels: features must hold pixel_count x dims values");
  }
  const std::size_t pixel_count = valid.size();
  Clustering out;
  out.labels.assign(pixel_count, -1);

  // Weighted copy of the features of an evenly strided sample of valid pixels.
  std::vector<float> weights(dims, 1.0f);
  FeatureWeights(dims, options, weights.data());
  std::vector<std::size_t> valid_index;
  for (std::size_t i = 0; i < pixel_count; ++i) {
    if (valid[i]) valid_index.push_back(i);
  }
  if (valid_index.empty()) return out;
  const std::size_t sample_count = std::min<std::size_t>(valid_index.size(), options.max_samples);
  std::vector<float> sample(sample_count * dims);
  for (std::size_t s = 0; s < sample_count; ++s) {
    const std::size_t pixel = valid_index[s * valid_index.size() / sample_count];
    for (int d = 0; d < dims; ++d) sample[s * dims + d] = features[pixel * dims + d] * weights[d];
  }

  // k-means++ seeding; stop early when every sample is within min_separation of a centre.
  std::mt19937_64 rng(options.seed);
  std::vector<float> centroids;
  std::vector<float> nearest_d2(sample_count, std::numeric_limits<float>::max());
  std::size_t next = static_cast<std::size_t>(Uniform01(rng) * sample_count);
  const float min_d2 = static_cast<float>(options.min_separation * options.min_separation);
  int k = 0;
  while (k < options.cluster_count) {
    centroids.insert(centroids.end(), sample.begin() + next * dims, sample.begin() + (next + 1) * dims);
    ++k;
    double total = 0.0;
    float max_d2 = 0.0f;
    for (std::size_t s = 0; s < sample_count; ++s) {
      const float d2 = SquaredDistance(&sample[s * dims], &centroids[static_cast<std::size_t>(k - 1) * dims], dims);
      nearest_d2[s] = std::min(nearest_d2[s], d2);
      total += nearest_d2[s];
      max_d2 = std::max(max_d2, nearest_d2[s]);
    }
    if (max_d2 <= min_d2 || total <= 0.0) break;
    double pick = Uniform01(rng) * total;
    next = sample_count - 1;
    for (std::size_t s = 0; s < sample_count; ++s) {
      pick -= nearest_d2[s];
      if (pick < 0.0) {
        next = s;
        break;
      }
    }
  }

  // Lloyd iterations on the sample.
  std::vector<int> sample_label(sample_count, -1);
  std::vector<double> sums(static_cast<std::size_t>(k) * dims);
  std::vector<std::int64_t> counts(k);
  for (int it = 0; it < options.iterations; ++it) {
    bool changed = false;
    for (std::size_t s = 0; s < sample_count; ++s) {
      const int c = Nearest(&sample[s * dims], centroids, k, dims, nullptr);
      if (c != sample_label[s]) changed = true;
      sample_label[s] = c;
    }
    if (!changed) break;
    std::fill(sums.begin(), sums.end(), 0.0);
    std::fill(counts.begin(), counts.end(), 0);
    for (std::size_t s = 0; s < sample_count; ++s) {
      const int c = sample_label[s];
      ++counts[c];
      for (int d = 0; d < dims; ++d) sums[static_cast<std::size_t>(c) * dims + d] += sample[s * dims + d];
    }
    for (int c = 0; c < k; ++c) {
      if (counts[c] == 0) continue;  // keeps its old centre; removed below if still empty
      for (int d = 0; d < dims; ++d) {
        centroids[static_cast<std::size_t>(c) * dims + d] =
            static_cast<float>(sums[static_cast<std::size_t>(c) * dims + d] / counts[c]);
      }
    }
  }

  // Every valid pixel to its nearest centre.
  ParallelFor(pixel_count, [&](std::size_t begin, std::size_t end) {
    float x[64];
    std::vector<float> heap;  // only for unusually wide features; once per chunk
    float* buffer = x;
    if (dims > 64) {
      heap.resize(dims);
      buffer = heap.data();
    }
    for (std::size_t i = begin; i < end; ++i) {
      if (!valid[i]) continue;
      for (int d = 0; d < dims; ++d) buffer[d] = features[i * dims + d] * weights[d];
      out.labels[i] = Nearest(buffer, centroids, k, dims, nullptr);
    }
  });

  // Drop empty clusters; number the rest in order of their first pixel (deterministic, readable).
  std::vector<int> remap(k, -1);
  int kept = 0;
  std::vector<float> kept_centroids;
  for (std::size_t i = 0; i < pixel_count; ++i) {
    const int c = out.labels[i];
    if (c < 0 || remap[c] >= 0) continue;
    remap[c] = kept++;
    kept_centroids.insert(kept_centroids.end(), centroids.begin() + static_cast<std::size_t>(c) * dims,
                          centroids.begin() + static_cast<std::size_t>(c + 1) * dims);
  }
  out.cluster_count = kept;
  out.centroids = std::move(kept_centroids);
  out.sizes.assign(kept, 0);
  for (std::size_t i = 0; i < pixel_count; ++i) {
    if (out.labels[i] < 0) continue;
    out.labels[i] = remap[out.labels[i]];
    ++out.sizes[out.labels[i]];
  }
  return out;
}

int NearestCluster(const Clustering& clustering, const float* features, int dims, const ClusteringOptions& options) {
  constexpr int kMaxDims = 64;
  if (clustering.cluster_count <= 0) return -1;
  if (dims > kMaxDims || clustering.centroids.size() != static_cast<std::size_t>(clustering.cluster_count) * dims) {
    throw std::invalid_argument("NearestCluster: features do not match the clustering");
  }
  float weights[kMaxDims];
  float x[kMaxDims];
  FeatureWeights(dims, options, weights);
  for (int d = 0; d < dims; ++d) x[d] = features[d] * weights[d];
  return Nearest(x, clustering.centroids, clustering.cluster_count, dims, nullptr);
}

}  // namespace u3mscan::fitting
