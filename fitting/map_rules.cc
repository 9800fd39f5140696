#include "fitting/map_rules.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "core/logging.h"
#include "core/parallel.h"
#include "fitting/observability.h"

namespace u3mscan::fitting {
namespace {
// Roughness at or below sqrt(kMinAlpha) = 0.032, GGX's alpha clamp, is the fit's lower bound (the
// lobe cannot get narrower).
constexpr double kHiddenLobeRoughness = 0.032;
}  // namespace

bool Usable(const FitOptions& options, const ClusterFit& cluster) {
  return !(cluster.rms_relative_residual > options.unusable_relative_rms);
}

std::vector<int> LeaveOutHiddenLobeRoughness(bool capture_saturated, std::vector<ClusterFit>* clusters) {
  std::vector<int> left_out;
  if (capture_saturated) return left_out;
  for (ClusterFit& c : *clusters) {
    ParameterEstimate& roughness = c.parameters[kRoughness];
    const ParameterEstimate& specular = c.parameters[kSpecular];
    if (!roughness.measured || roughness.value > kHiddenLobeRoughness || specular.measured) continue;
    char buffer[360];
    std::snprintf(buffer, sizeof buffer,
                  "the fit ended at the lower bound (roughness %.3g <= %.3g) with specular held at its default and no "
                  "saturated highlight in the capture: a lobe that narrow falls between the lights, so the solve hid "
                  "the held specular lobe instead of measuring a roughness",
                  roughness.value, kHiddenLobeRoughness);
    roughness.measured = false;
    roughness.std_dev = std::numeric_limits<double>::infinity();
    roughness.reason = buffer;
    left_out.push_back(c.id);
  }
  return left_out;
}

ParameterMask LeaveOutMapsNotKnownAsAWhole(const FitOptions& options, const std::vector<std::size_t>& cluster_weight,
                                           std::vector<ClusterFit>* clusters,
                                           const std::function<void(int, const ParameterMask&)>& refit) {
  const double max_std = options.observability.max_std;
  ParameterMask left_out{};  // so far; each round adds to it, so the rounds end
  for (;;) {
    ParameterMask now{};
    std::array<std::string, kFitParameterCount> reason;
    for (int i = 0; i < kFitParameterCount; ++i) {
      if (left_out[i]) continue;
      double variance = 0.0, weight = 0.0;
      int worst = -1;
      for (const ClusterFit& c : *clusters) {
        const ParameterEstimate& e = c.parameters[i];
        if (!e.measured || !std::isfinite(e.std_dev) || !Usable(options, c)) continue;
        const double w = static_cast<double>(cluster_weight[c.id]);
        variance += w * e.std_dev * e.std_dev;
        weight += w;
        if (worst < 0 || e.std_dev > (*clusters)[worst].parameters[i].std_dev) worst = c.id;
      }
      const double pooled = weight > 0.0 ? std::sqrt(variance / weight) : 0.0;
      if (!(pooled > max_std)) continue;
      now[i] = true;
      ObservabilityContext hint_context;
      hint_context.max_grazing_weight = -1.0;  // per cluster only
      char buffer[200];
      std::snprintf(buffer, sizeof buffer,
                    "not constrained by this capture (posterior std pooled over the clusters %.3g > %.3g; worst "
                    "cluster %d: %.3g); ",
                    pooled, max_std, worst, (*clusters)[worst].parameters[i].std_dev);
      reason[i] = buffer + LeaveOutHint(static_cast<FitParameter>(i), hint_context);
    }
    if (now == ParameterMask{}) return left_out;
    std::vector<int> again;
    std::vector<ParameterMask> measured_now(clusters->size());  // what each cluster measured of `now`
    for (const ClusterFit& c : *clusters) {
      for (int i = 0; i < kFitParameterCount; ++i) measured_now[c.id][i] = now[i] && c.parameters[i].measured;
      if (Usable(options, c) && measured_now[c.id] != ParameterMask{}) again.push_back(c.id);
    }
    for (int i = 0; i < kFitParameterCount; ++i) left_out[i] = left_out[i] || now[i];
    ParallelFor(again.size(), [&](std::size_t begin, std::size_t end) {
      for (std::size_t j = begin; j < end; ++j) refit(again[j], left_out);
    });
    for (ClusterFit& c : *clusters) {
      for (int i = 0; i < kFitParameterCount; ++i) {
        if (!now[i]) continue;
        ParameterEstimate& e = c.parameters[i];
        e.measured = false;  // whatever the refit says: the maps do not hold it
        e.std_dev = std::numeric_limits<double>::infinity();
        e.value = FitParameterDefault(static_cast<FitParameter>(i));
        if (measured_now[c.id][i]) e.reason = reason[i];  // the others keep their own reason
      }
    }
    LogInfo() << "fitting: " << again.size() << " clusters fitted again without the parameters the maps leave out";
  }
}

bool RefinedPerPixel(const FitOptions& options, FitParameter parameter) {
  if (options.mode != FitMode::kPerPixel) return false;
  return parameter == FitParameter::kRoughness ||
         (parameter == FitParameter::kSpecular && options.refine_specular_per_pixel);
}

std::array<std::string, kFitParameterCount> HoldUniformClusterMaps(
    const FitOptions& options, const std::vector<std::size_t>& cluster_weight, std::vector<ClusterFit>* clusters,
    const std::function<void(int, const ParameterMask&, const ParameterVector&)>& refit) {
  std::array<std::string, kFitParameterCount> verdict;
  ParameterMask held{};  // so far; each round adds to it, so the rounds end
  ParameterVector values = DefaultParameters();
  // Each cluster's own estimate of a held parameter, taken when the hold began (a refit knows the
  // parameter only as fixed).
  std::vector<std::array<ParameterEstimate, kFitParameterCount>> own(clusters->size());
  std::vector<ParameterMask> holds(clusters->size());  // what each cluster holds of `held`
  auto measured = [](const ParameterEstimate& e) { return e.measured && std::isfinite(e.std_dev); };
  // A cluster's value in the maps: its own where it measured the parameter, else the default.
  auto in_maps = [&](const ParameterEstimate& e, int i) {
    return measured(e) ? e.value : FitParameterDefault(static_cast<FitParameter>(i));
  };
  for (;;) {
    ParameterMask now{};
    for (int i = 0; i < kFitParameterCount; ++i) {
      if (held[i] || RefinedPerPixel(options, static_cast<FitParameter>(i))) continue;
      // The map as the pixels would hold it: each usable cluster's value in the maps (the default
      // where it did not measure it), against the std pooled over those that measured it.
      double weight = 0.0, sum = 0.0, sum2 = 0.0, variance = 0.0, measuring_weight = 0.0;
      for (const ClusterFit& c : *clusters) {
        if (!Usable(options, c)) continue;
        const ParameterEstimate& e = c.parameters[i];
        const double value = in_maps(e, i);
        const double w = static_cast<double>(cluster_weight[c.id]);
        weight += w;
        sum += w * value;
        sum2 += w * value * value;
        if (!measured(e)) continue;
        measuring_weight += w;
        variance += w * e.std_dev * e.std_dev;
      }
      if (!(measuring_weight > 0.0)) continue;
      const double mean = sum / weight;
      const double spread = std::sqrt(std::max(0.0, sum2 / weight - mean * mean));
      const double pooled = std::sqrt(variance / measuring_weight);
      if (!IsUniformWithinNoise(spread, pooled, options.observability)) continue;
      now[i] = true;
      values[i] = mean;
      char buffer[240];
      std::snprintf(buffer, sizeof buffer,
                    "uniform within noise over the clusters (spread %.3g, pooled uncertainty %.3g): one constant, "
                    "every cluster fitted with it",
                    spread, pooled);
      verdict[i] = buffer;
    }
    if (now == ParameterMask{}) return verdict;
    for (int i = 0; i < kFitParameterCount; ++i) held[i] = held[i] || now[i];
    // Every usable cluster: the constant covers the pixels of those that did not measure it too
    // (they held the default so far).
    std::vector<int> again;
    for (const ClusterFit& c : *clusters) {
      if (!Usable(options, c)) continue;
      bool moves = false;
      for (int i = 0; i < kFitParameterCount; ++i) {
        if (!now[i]) continue;
        const ParameterEstimate& e = c.parameters[i];
        holds[c.id][i] = true;
        own[c.id][i] = e;
        moves = moves || std::abs(in_maps(e, i) - values[i]) > options.observability.uniform_abs_tolerance;
      }
      if (moves) again.push_back(c.id);
    }
    ParallelFor(again.size(), [&](std::size_t begin, std::size_t end) {
      for (std::size_t j = begin; j < end; ++j) refit(again[j], held, values);
    });
    for (ClusterFit& c : *clusters) {
      for (int i = 0; i < kFitParameterCount; ++i) {
        if (!holds[c.id][i]) continue;
        c.parameters[i] = own[c.id][i];
        c.parameters[i].value = values[i];
      }
    }
    LogInfo() << "fitting: " << again.size() << " clusters fitted again with the maps uniform within noise held";
  }
}

}  // namespace u3mscan::fitting
