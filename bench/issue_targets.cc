#include "bench/issue_targets.h"

#include <cmath>
#include <sstream>

#include "bench/table_cells.h"

namespace u3mscan::bench {
namespace {

// A figure against its limit: the figure and a check or a cross; counts into `met` / `judged`.
struct Tally {
  int met = 0, judged = 0;
  std::string Cell(double value, double limit, int digits) {
    if (!std::isfinite(value)) return "";
    ++judged;
    const bool ok = value < limit;
    met += ok;
    return Fixed(value, digits) + (ok ? " ✓" : " ✗");
  }
  std::string ParameterCell(const BenchRow& row, const std::string& name, double limit) {
    for (const ParameterError& p : row.evaluation.parameters) {
      if (p.name != name) continue;
      return p.measured ? Cell(p.mean_abs_error, limit, 3) : "not measured";
    }
    return "";
  }
};

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
    const Evaluation& e = r.evaluation;
    const double height =
        std::isfinite(e.height_levelled_rmse_percent) ? e.height_levelled_rmse_percent : e.height_rmse_percent;
    Tally t;
    s << "| " << r.c.RunId() << " | " << t.Cell(e.normal_mean_deg, NormalTargetDeg(r.c.scene), 2) << " | "
      << t.Cell(e.base_color_de_mean, kTargetColourDe, 2) << " | " << t.Cell(height, kTargetHeightPercent, 2) << " | "
      << t.ParameterCell(r, "roughness", kTargetRoughness) << " | " << t.ParameterCell(r, "specular", kTargetSpecular)
      << " | " << t.ParameterCell(r, "sheen", kTargetSheen) << " | " << t.Cell(100.0 * e.rerender_relative_rmse, kTargetRerenderPercent, 2) << " | "
      << t.Cell(100.0 * r.held_out_rmse, kTargetRerenderPercent, 2) << " | " << t.met << " of " << t.judged << " | "
      << (e.rerender_truth_maps_relative_rmse > 0.0 ? Fixed(100.0 * e.rerender_truth_maps_relative_rmse, 2) : "-")
      << " |\n";
  }
  return s.str();
}

}  // namespace u3mscan::bench
