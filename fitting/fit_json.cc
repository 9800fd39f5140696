// fit.json: FitResultToJson (principled_fit.h), the fit report in the format of docs/fitting.md,
// "Output (`FitResult`) and `fit.json`".
#include "fitting/principled_fit.h"

#include <cmath>
#include <cstdio>
#include <sstream>
#include <string>

namespace u3mscan::fitting {
namespace {

std::string JsonNumber(double v) {
  if (!std::isfinite(v)) return "null";
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.6g", v);
  return buffer;
}

std::string JsonString(const std::string& s) {
  std::string out = "\"";
  for (const char ch : s) {
    switch (ch) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\t': out += "\\t"; break;
      case '\r': out += "\\r"; break;
      default:
        if (static_cast<unsigned char>(ch) < 0x20) {
          char buffer[8];
          std::snprintf(buffer, sizeof buffer, "\\u%04x", ch);
          out += buffer;
        } else {
          out += ch;
        }
    }
  }
  return out + "\"";
}

}  // namespace

std::string FitResultToJson(const FitResult& result) {
  std::ostringstream j;
  j << "{\n  \"maps\": {";
  for (int i = 0; i < kFitParameterCount; ++i) {
    const MapReport& m = result.maps[i];
    j << (i ? "," : "") << "\n    " << JsonString(FitParameterName(i))
      << ": {\"u3m\": " << JsonString(U3mParameterName(static_cast<FitParameter>(i))) << ", \"measured\": "
      << (m.measured ? "true" : "false") << ", \"constant\": " << (m.constant ? "true" : "false")
      << ", \"texture\": " << (m.measured && !m.constant ? "true" : "false") << ", \"value\": " << JsonNumber(m.value)
      << ", \"spread\": " << JsonNumber(m.spread) << ", \"reason\": " << JsonString(m.reason)
      << ", \"reliable\": " << (m.reliable ? "true" : "false")
      << ", \"unreliable_reason\": " << JsonString(m.unreliable_reason) << "}";
  }
  const MapReport& turn = result.rotation_report;
  j << ",\n    \"anisotropy_rotation\": {\"u3m\": \"anisotropy_rotation\", \"unit\": \"deg\", \"measured\": "
    << (turn.measured ? "true" : "false") << ", \"constant\": " << (turn.constant ? "true" : "false")
    << ", \"texture\": " << (turn.measured && !turn.constant ? "true" : "false") << ", \"value\": " << JsonNumber(turn.value)
    << ", \"spread\": " << JsonNumber(turn.spread) << ", \"reason\": " << JsonString(turn.reason)
    << ", \"reliable\": " << (turn.reliable ? "true" : "false")
    << ", \"unreliable_reason\": " << JsonString(turn.unreliable_reason) << "}";
  j << "\n  },\n  \"not_measured\": [";
  bool first = true;
  for (int i = 0; i < kFitParameterCount; ++i) {
    if (result.maps[i].measured) continue;
    j << (first ? "" : ",") << "\n    {\"parameter\": " << JsonString(FitParameterName(i))
      << ", \"written_as\": " << JsonNumber(result.maps[i].value) << ", \"reason\": " << JsonString(result.maps[i].reason)
      << "}";
    first = false;
  }
  j << (first ? "" : "\n  ") << "],\n  \"clusters\": [";
  for (std::size_t c = 0; c < result.clusters.size(); ++c) {
    const ClusterFit& f = result.clusters[c];
    j << (c ? "," : "") << "\n    {\"id\": " << f.id << ", \"pixels\": " << f.pixel_count
      << ", \"samples\": " << f.sample_count << ", \"converged\": " << (f.converged ? "true" : "false")
      << ", \"iterations\": " << f.iterations << ", \"normal_passes\": " << f.normal_passes
      << ", \"normal_change_deg\": " << JsonNumber(f.normal_change_deg) << ", \"initial_cost\": " << JsonNumber(f.initial_cost)
      << ", \"final_cost\": " << JsonNumber(f.final_cost)
      << ", \"rms_relative_residual\": " << JsonNumber(f.rms_relative_residual)
      << ", \"saturated_share\": " << JsonNumber(f.saturated_share)
      << ", \"highlight_share\": " << JsonNumber(f.highlight_share)
      << ", \"anisotropy_rotation_deg\": " << JsonNumber(f.anisotropy_rotation_deg) << ", \"mean_base_color_linear\": ["
      << JsonNumber(f.mean_base_color(0)) << ", " << JsonNumber(f.mean_base_color(1)) << ", "
      << JsonNumber(f.mean_base_color(2)) << "], \"message\": " << JsonString(f.message) << ",\n     \"parameters\": {";
    for (int i = 0; i < kFitParameterCount; ++i) {
      const ParameterEstimate& e = f.parameters[i];
      j << (i ? ", " : "") << "\n       " << JsonString(FitParameterName(i)) << ": {\"value\": " << JsonNumber(e.value)
        << ", \"std\": " << JsonNumber(e.std_dev) << ", \"measured\": " << (e.measured ? "true" : "false")
        << ", \"reason\": " << JsonString(e.reason) << ", \"reliable\": " << (e.reliable ? "true" : "false")
        << ", \"unreliable_reason\": " << JsonString(e.unreliable_reason) << "}";
    }
    j << "}}";
  }
  const ConvergenceReport& cr = result.convergence;
  j << "\n  ],\n  \"convergence\": {\"all_converged\": " << (cr.all_converged ? "true" : "false")
    << ", \"clusters_failed\": " << cr.clusters_failed << ", \"pixels_fitted\": " << cr.pixels_fitted
    << ", \"pixels_refined\": " << cr.pixels_refined << ", \"messages\": [";
  for (std::size_t i = 0; i < cr.messages.size(); ++i) j << (i ? ", " : "") << JsonString(cr.messages[i]);
  const StageTimes& t = result.times;
  j << "]},\n  \"times_s\": {\"gather\": " << JsonNumber(t.gather_s) << ", \"clustering\": " << JsonNumber(t.clustering_s)
    << ", \"cluster_fit\": " << JsonNumber(t.cluster_fit_s) << ", \"observability\": " << JsonNumber(t.observability_s)
    << ", \"per_pixel\": " << JsonNumber(t.per_pixel_s) << ", \"total\": " << JsonNumber(t.total_s) << "},\n";
  const FitOptions& o = result.options;
  const char* loss = o.robust_loss.kind == RobustLossKind::kHuber    ? "huber"
                     : o.robust_loss.kind == RobustLossKind::kCauchy ? "cauchy"
                                                                     : "none";
  j << "  \"options\": {\"cluster_count\": " << o.clustering.cluster_count
    << ", \"samples_per_cluster\": " << o.samples_per_cluster << ", \"noise_relative\": " << JsonNumber(o.noise_relative)
    << ", \"noise_floor\": " << JsonNumber(o.noise_floor) << ", \"robust_loss\": " << JsonString(loss)
    << ", \"robust_scale_sigma\": " << JsonNumber(o.robust_loss.scale)
    << ", \"observability_max_std\": " << JsonNumber(o.observability.max_std)
    << ", \"observability_effective_pixels\": " << o.observability.effective_pixels
    << ", \"fit_anisotropy_rotation\": " << (o.fit_anisotropy_rotation ? "true" : "false")
    << ", \"mode\": " << JsonString(FitModeName(o.mode)) << ", \"seed\": " << o.clustering.seed
    << "}\n}\n";
  return j.str();
}

}  // namespace u3mscan::fitting
