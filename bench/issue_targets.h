#pragma once
// The accuracy targets of issue 5 (reconstruction) and issue 6 (fitting), and which of them a run
// meets: `u3mscan evaluate` prints the verdicts of one run, bench.md's "Against the issues'
// targets" those of each balanced bench run (docs/bench.md).
//
// Every figure is the run's own evaluation (bench/evaluate.h) against the synthetic truth: normal
// mean angular error (deg), CIEDE2000 of the written base colour, height RMSE as % of the truth's
// height range (against the truth levelled as the run when the run levels), mean absolute error
// of roughness, specular and sheen where the run measured them, and the relative RMSE of the
// re-rendered material under lights that were not in the capture (and, for held-out runs, under
// the held-out lights' own photographs).

#include <limits>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench/evaluate.h"

namespace u3mscan::bench {

struct BenchRow;

// The issues' limits; a figure meets its target when it is below the limit.
inline constexpr double kTargetNormalDeg = 1.0;             // Lambertian-dominant fabrics
inline constexpr double kTargetNormalSatinVelvetDeg = 2.0;  // satin and velvet
inline constexpr double kTargetColourDe = 1.5;              // base colour CIEDE2000
inline constexpr double kTargetHeightPercent = 2.0;         // of the height range
inline constexpr double kTargetRoughness = 0.05;
inline constexpr double kTargetSpecular = 0.1;
inline constexpr double kTargetSheen = 0.1;                 // where measured
inline constexpr double kTargetRerenderPercent = 2.0;       // lights left out of the fit

// The normal limit for a synthetic scene: 2 deg for satin and every velvet (velvet_bumps,
// velvet_mismatch), 1 deg for the rest (an unnamed scene too).
double NormalTargetDeg(const std::string& scene);

// One figure of a run against its limit.
struct TargetCheck {
  std::string figure;  // "normal mean deg", "base dE", "height %", "roughness err", ...
  double value = std::numeric_limits<double>::quiet_NaN();  // NaN: the run has no such figure
  double limit = 0.0;
  bool not_measured = false;  // a parameter the run left out: judged neither way
  int digits = 2;             // decimals the figure is printed with
  bool Judged() const;        // measured and finite
  bool Met() const;           // judged and below the limit
};

// Every figure the issues set a limit for, in the order of bench.md's table: normal mean, base
// colour, height, roughness, specular, sheen, re-render (truth), held-out photographs (NaN
// held_out_rmse, a relative RMSE: the run held none out). The normal's limit is
// NormalTargetDeg(evaluation.scene).
std::vector<TargetCheck> CheckAgainstTheTargets(const Evaluation& evaluation,
                                                double held_out_rmse = std::numeric_limits<double>::quiet_NaN());

// "<value> ✓" (met), "<value> ✗" (not), "not measured", or "" (the run has no such figure).
std::string TargetCell(const TargetCheck& check);

// For people (`u3mscan evaluate`): a heading line with the scene and how many judged figures meet
// their target, then one line per figure with its value, its verdict and its limit.
std::string TargetsToText(const std::vector<TargetCheck>& checks, const std::string& scene);
// [{figure, value (null when absent), limit, not_measured, met (null when not judged)}, ...]
nlohmann::json TargetsToJson(const std::vector<TargetCheck>& checks);

// The markdown section (heading included): one line per successful run of preset balanced in the
// groups matrix, model-mismatch, held-out and camera-finer; each figure's TargetCell, how many of
// the row's judged figures meet their target, then the truth's own maps' re-render error for
// reference ("-" where Evaluation gives none: maps not coarser than the truth).
std::string IssueTargetsSection(const std::vector<BenchRow>& rows);

}  // namespace u3mscan::bench
