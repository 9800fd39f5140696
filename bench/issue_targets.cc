#include "bench/issue_targets.h"

#include <cmath>
#include <iomanip>
#include <sstream>

#include "bench/bench.h"
#include "bench/table_cells.h"
#include "pipeline/json_number.h"

namespace u3mscan::bench {
namespace {

// A parameter's mean absolute error against its limit; not measured: judged neither way.
TargetCheck ParameterCheck(const Evaluation& e, const std::string& name, double limit) {
  TargetCheck check{name + " err", std::numeric_limits<double>::quiet_NaN(), limit, false, 3};
  for (const ParameterError& p : e.parameters) {
    if (p.name != name) continue;
    check.not_measured = !p.measured;
    if (p.measured) check.value = p.mean_abs_error;
  }
  return check;
}

// How many of the checks are judged, and how many of those meet their target.
struct MetCount {
  int met = 0, judged = 0;
};
MetCount CountMet(const std::vector<TargetCheck>& checks) {
  MetCount count;
  for (const TargetCheck& check : checks) {
    count.judged += check.Judged();
    count.met += check.Met();
  }
  return count;
}

bool JudgedAgainstTheTargets(const BenchRow& r) {
  const std::string& g = r.c.group;
  return r.status == "ok" && r.c.preset == "balanced" &&
         (g == "matrix" || g == "model-mismatch" || g == "held-out" || g == "camera-finer");
}

}  // namespace

double NormalTargetDeg(const std::string& scene) {
  const bool satin_or_velvet = scene.rfind("satin", 0) == 0 || scene.rfind("velvet", 0) == 0;
  return satin_or_velvet ? kTargetNormalSatinVelvetDeg : kTargetNormalDeg;
}

bool TargetCheck::Judged() const { return !not_measured && std::isfinite(value); }
bool TargetCheck::Met() const { return Judged() && value < limit; }

std::vector<TargetCheck> CheckAgainstTheTargets(const Evaluation& e, double held_out_rmse) {
  const double height =
      std::isfinite(e.height_levelled_rmse_percent) ? e.height_levelled_rmse_percent : e.height_rmse_percent;
  return {{"normal mean deg", e.normal_mean_deg, NormalTargetDeg(e.scene)},
          {"base dE", e.base_color_de_mean, kTargetColourDe},
          {"height %", height, kTargetHeightPercent},
          ParameterCheck(e, "roughness", kTargetRoughness),
          ParameterCheck(e, "specular", kTargetSpecular),
          ParameterCheck(e, "sheen", kTargetSheen),
          {"re-render %", 100.0 * e.rerender_relative_rmse, kTargetRerenderPercent},
          {"held-out photographs %", 100.0 * held_out_rmse, kTargetRerenderPercent}};
}

std::string TargetCell(const TargetCheck& check) {
  if (check.not_measured) return "not measured";
  if (!check.Judged()) return "";
  return Fixed(check.value, check.digits) + (check.Met() ? " ✓" : " ✗");
}

std::string TargetsToText(const std::vector<TargetCheck>& checks, const std::string& scene) {
  std::ostringstream s;
  const MetCount count = CountMet(checks);
  s << "issues' targets (scene " << (scene.empty() ? "unnamed" : scene) << ", docs/bench.md): " << count.met << " of "
    << count.judged << " met\n";
  for (const TargetCheck& check : checks) {
    const std::string cell = TargetCell(check);
    if (cell.empty()) continue;
    s << "  " << std::left << std::setw(24) << check.figure << std::right << cell;
    if (!check.not_measured) s << "  (limit " << Fixed(check.limit, check.digits) << ")";
    s << "\n";
  }
  return s.str();
}

nlohmann::json TargetsToJson(const std::vector<TargetCheck>& checks) {
  nlohmann::json out = nlohmann::json::array();
  for (const TargetCheck& check : checks) {
    out.push_back({{"figure", check.figure},
                   {"value", FiniteOrNull(check.value)},
                   {"limit", check.limit},
                   {"not_measured", check.not_measured},
                   {"met", check.Judged() ? nlohmann::json(check.Met()) : nlohmann::json()}});
  }
  return out;
}

std::string IssueTargetsSection(const std::vector<BenchRow>& rows) {
  std::ostringstream s;
  s << "\n## Against the issues' targets (preset balanced)\n\n"
       "Limits: normal mean < 1 deg (< 2 on satin and velvet), base colour CIEDE2000 < 1.5, height RMSE < 2 % of the "
       "range (against the truth levelled as the run), roughness < 0.05, specular < 0.1, sheen < 0.1 where measured, "
       "re-render of lights left out of the fit < 2 % (the truth's renders; for held-out runs also the held-out "
       "photographs). ✓ below the limit, ✗ not. The last column is what the truth's own parameters, averaged onto "
       "the maps' grid, re-render to: a material with one normal per map pixel cannot reproduce what its pixel's "
       "facets do, so the truth's renders are a harder reference than the photographs (\"-\": maps on the truth's own "
       "grid or finer, where the truth is rendered as it is).\n\n"
       "| run | normal mean deg | base dE | height % | roughness err | specular err | "
       "sheen err | re-render % | held-out photographs % | met | truth's own maps re-render % (not judged) |\n"
       "|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const BenchRow& r : rows) {
    if (!JudgedAgainstTheTargets(r)) continue;
    const std::vector<TargetCheck> checks = CheckAgainstTheTargets(r.evaluation, r.held_out_rmse);
    s << "| " << r.c.RunId() << " | ";
    for (const TargetCheck& check : checks) s << TargetCell(check) << " | ";
    const MetCount count = CountMet(checks);
    const double truth_maps = r.evaluation.rerender_truth_maps_relative_rmse;
    s << count.met << " of " << count.judged << " | " << (truth_maps > 0.0 ? Fixed(100.0 * truth_maps, 2) : "-") << " |\n";
  }
  return s.str();
}

}  // namespace u3mscan::bench
