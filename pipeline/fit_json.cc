#include "pipeline/fit_json.h"

#include <cmath>

#include "pipeline/json_number.h"

namespace u3mscan::pipeline {
namespace {

// Keys in the order docs/fitting.md gives them: the decisions first, as an operator reads them.
using json = nlohmann::ordered_json;
using fitting::kFitParameterCount;

// A map's decision (maps.<parameter> and maps.anisotropy_rotation), under its U3M key; `unit`
// only where the value is not in [0, 1].
json MapJson(const fitting::MapReport& m, const char* u3m_key, const char* unit = nullptr) {
  json out = {{"u3m", u3m_key}};
  if (unit != nullptr) out["unit"] = unit;
  out.update(json{{"measured", m.measured},
          {"constant", m.constant},
          {"texture", m.measured && !m.constant},
          {"value", FiniteOrNull<json>(m.value)},
          {"spread", FiniteOrNull<json>(m.spread)},
          {"reason", m.reason},
          {"reliable", m.reliable},
          {"unreliable_reason", m.unreliable_reason}});
  return out;
}

json ClusterJson(const fitting::ClusterFit& f) {
  // The per-pixel step's prior std toward the cluster's value, for the parameters it refines.
  json pixel_prior_std = json::object();
  for (int i = 0; i < kFitParameterCount; ++i) {
    if (f.pixel_prior_std[i] > 0.0) pixel_prior_std[fitting::FitParameterName(i)] = FiniteOrNull<json>(f.pixel_prior_std[i]);
  }
  json parameters = json::object();
  for (int i = 0; i < kFitParameterCount; ++i) {
    const fitting::ParameterEstimate& e = f.parameters[i];
    parameters[fitting::FitParameterName(i)] = {{"value", FiniteOrNull<json>(e.value)},       {"std", FiniteOrNull<json>(e.std_dev)},
                                                {"measured", e.measured},          {"reason", e.reason},
                                                {"reliable", e.reliable},          {"unreliable_reason", e.unreliable_reason}};
  }
  return {{"id", f.id},
          {"pixels", f.pixel_count},
          {"samples", f.sample_count},
          {"converged", f.converged},
          {"iterations", f.iterations},
          {"normal_passes", f.normal_passes},
          {"normal_change_deg", FiniteOrNull<json>(f.normal_change_deg)},
          {"initial_cost", FiniteOrNull<json>(f.initial_cost)},
          {"final_cost", FiniteOrNull<json>(f.final_cost)},
          {"rms_relative_residual", FiniteOrNull<json>(f.rms_relative_residual)},
          {"saturated_share", FiniteOrNull<json>(f.saturated_share)},
          {"highlight_share", FiniteOrNull<json>(f.highlight_share)},
          {"anisotropy_rotation_deg", FiniteOrNull<json>(f.anisotropy_rotation_deg)},
          {"pixel_prior_std", pixel_prior_std},
          {"mean_base_color_linear",
           {FiniteOrNull<json>(f.mean_base_color(0)), FiniteOrNull<json>(f.mean_base_color(1)), FiniteOrNull<json>(f.mean_base_color(2))}},
          {"message", f.message},
          {"parameters", parameters}};
}

const char* LossName(fitting::RobustLossKind kind) {
  switch (kind) {
    case fitting::RobustLossKind::kHuber: return "huber";
    case fitting::RobustLossKind::kCauchy: return "cauchy";
    case fitting::RobustLossKind::kNone: break;
  }
  return "none";
}

}  // namespace

json FitResultToJson(const fitting::FitResult& result) {
  json maps = json::object();
  json not_measured = json::array();
  for (int i = 0; i < kFitParameterCount; ++i) {
    const fitting::MapReport& m = result.maps[i];
    maps[fitting::FitParameterName(i)] = MapJson(m, fitting::U3mParameterName(static_cast<fitting::FitParameter>(i)));
    if (!m.measured) {
      not_measured.push_back({{"parameter", fitting::FitParameterName(i)}, {"written_as", FiniteOrNull<json>(m.value)}, {"reason", m.reason}});
    }
  }
  maps["anisotropy_rotation"] = MapJson(result.rotation_report, "anisotropy_rotation", "deg");

  json clusters = json::array();
  for (const fitting::ClusterFit& f : result.clusters) clusters.push_back(ClusterJson(f));

  const fitting::ConvergenceReport& c = result.convergence;
  const fitting::StageTimes& t = result.times;
  const fitting::FitOptions& o = result.options;
  return {{"maps", maps},
          {"not_measured", not_measured},
          {"clusters", clusters},
          {"convergence",
           {{"all_converged", c.all_converged},
            {"clusters_failed", c.clusters_failed},
            {"pixels_fitted", c.pixels_fitted},
            {"pixels_refined", c.pixels_refined},
            {"messages", c.messages}}},
          {"times_s",
           {{"gather", FiniteOrNull<json>(t.gather_s)},
            {"clustering", FiniteOrNull<json>(t.clustering_s)},
            {"cluster_fit", FiniteOrNull<json>(t.cluster_fit_s)},
            {"observability", FiniteOrNull<json>(t.observability_s)},
            {"per_pixel", FiniteOrNull<json>(t.per_pixel_s)},
            {"total", FiniteOrNull<json>(t.total_s)}}},
          {"options",
           {{"cluster_count", o.clustering.cluster_count},
            {"samples_per_cluster", o.samples_per_cluster},
            {"noise_relative", FiniteOrNull<json>(o.noise_relative)},
            {"noise_floor", FiniteOrNull<json>(o.noise_floor)},
            {"robust_loss", LossName(o.robust_loss.kind)},
            {"robust_scale_sigma", FiniteOrNull<json>(o.robust_loss.scale)},
            {"observability_max_std", FiniteOrNull<json>(o.observability.max_std)},
            {"observability_effective_pixels", o.observability.effective_pixels},
            {"fit_anisotropy_rotation", o.fit_anisotropy_rotation},
            {"pixel_prior_std", FiniteOrNull<json>(o.pixel_prior_std)},
            {"pixel_prior_from_samples", o.pixel_prior_from_samples},
            {"refine_normal_with_lobe", o.refine_normal_with_lobe},
            {"mode", fitting::FitModeName(o.mode)},
            {"seed", o.clustering.seed}}}};
}

}  // namespace u3mscan::pipeline
