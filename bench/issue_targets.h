#pragma once
// The accuracy targets of issue 5 (reconstruction) and issue 6 (fitting), and which of them each
// bench run meets: the "Against the issues' targets" section of bench.md (docs/bench.md).
//
// Every figure is the run's own evaluation (bench/evaluate.h) against the synthetic truth: normal
// mean angular error (deg), CIEDE2000 of the written base colour, height RMSE as % of the truth's
// height range (against the truth levelled as the run when the run levels), mean absolute error
// of roughness, specular and sheen where the run measured them, and the relative RMSE of the
// re-rendered material under lights that were not in the capture (and, for held-out runs, under
// the held-out lights' own photographs).

#include <string>
#include <vector>

#include "bench/bench.h"

namespace u3mscan::bench {

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
// velvet_mismatch), 1 deg for the rest.
double NormalTargetDeg(const std::string& scene);

// The markdown section (heading included): one line per successful run of preset balanced in the
// groups matrix, model-mismatch, held-out and camera-finer; each figure followed by a check or a
// cross against its limit ("not measured" parameters count neither way), and how many of the
// row's figures meet their target; then the truth's own maps' re-render error, for reference
// ("-" where Evaluation gives none: maps not coarser than the truth).
std::string IssueTargetsSection(const std::vector<BenchRow>& rows);

}  // namespace u3mscan::bench
