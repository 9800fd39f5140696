#include "pipeline/presets.h"

#include <stdexcept>

namespace u3mscan {

std::string PresetName(Preset preset) {
  switch (preset) {
    case Preset::kFast: return "fast";
    case Preset::kBalanced: return "balanced";
    case Preset::kBest: return "best";
  }
  return "balanced";
}

Preset ParsePreset(const std::string& name) {
  if (name == "fast") return Preset::kFast;
  if (name == "balanced") return Preset::kBalanced;
  if (name == "best") return Preset::kBest;
  throw std::invalid_argument("preset must be fast, balanced or best; got \"" + name + "\"");
}

StageOptions OptionsForPreset(Preset preset) {
  using reconstruction::Integrator;
  using reconstruction::PsSolver;
  StageOptions options;
  switch (preset) {
    case Preset::kFast:
      options.photometric_stereo.solver = PsSolver::kLeastSquares;
      options.photometric_stereo.max_near_iterations = 3;
      options.integration.method = Integrator::kDct;
      options.fit.clustering.cluster_count = 4;
      options.fit.samples_per_cluster = 96;
      options.fit.grid_samples_per_cluster = 24;
      options.fit.max_iterations = 30;
      options.fit.mode = fitting::FitMode::kClusters;
      options.fit.normal_refinement_max_passes = 3;
      break;
    case Preset::kBalanced:
      options.photometric_stereo.solver = PsSolver::kRobust;
      options.integration.method = Integrator::kDct;
      break;
    case Preset::kBest:
      options.photometric_stereo.solver = PsSolver::kRobust;
      options.photometric_stereo.irls_iterations = 25;
      options.photometric_stereo.max_near_iterations = 12;
      options.photometric_stereo.integration.method = Integrator::kRobust;
      options.integration.method = Integrator::kRobust;
      options.fit.clustering.cluster_count = 12;
      options.fit.samples_per_cluster = 384;
      options.fit.grid_samples_per_cluster = 96;
      options.fit.pixel_iterations = 6;
      options.fit.normal_refinement_tolerance_deg = 0.01;
      break;
  }
  return options;
}

}  // namespace u3mscan
