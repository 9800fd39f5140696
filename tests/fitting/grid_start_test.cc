#include "fitting/grid_start.h"

#include <gtest/gtest.h>

#include <cmath>

namespace u3mscan::fitting {
namespace {

// A cost whose minimum (roughness 0.3, specular 0.25, sheen 0.7) lies on the grid, with a valley
// that trades roughness against specular: with specular held elsewhere, the best roughness moves.
double ValleyCost(const ParameterVector& p) {
  const double lobe = p[kSpecular] / (p[kRoughness] * p[kRoughness]);  // peak height of the lobe
  return std::pow(lobe - 0.25 / 0.09, 2) + 0.1 * std::pow(p[kSpecular] - 0.25, 2) + std::pow(p[kSheen] - 0.7, 2);
}

TEST(GridStart, FindsTheGridMinimumOverTheCandidates) {
  ParameterMask candidates{};
  candidates[kRoughness] = candidates[kSpecular] = candidates[kSheen] = candidates[kSpecularTint] = true;
  const ParameterVector start = GridStart(candidates, DefaultParameters(), /*search_sheen=*/true, ValleyCost);
  EXPECT_DOUBLE_EQ(start[kRoughness], 0.3);
  EXPECT_DOUBLE_EQ(start[kSpecular], 0.25);
  EXPECT_DOUBLE_EQ(start[kSheen], 0.7);
  EXPECT_DOUBLE_EQ(start[kSpecularTint], 0.0);
  const ParameterVector no_sheen = GridStart(candidates, DefaultParameters(), /*search_sheen=*/false, ValleyCost);
  EXPECT_DOUBLE_EQ(no_sheen[kSheen], 0.0) << "without grazing light a candidate sheen starts at 0";
}

// A refit with specular held by the maps (left out at its default 0.5, or held at the clusters'
// uniform value) must start, and so be fitted, with that value: the grid's own specular 0.25 here
// paired the cluster's roughness with a lobe the maps do not write.
TEST(GridStart, AHeldParameterKeepsItsValueAndTheOthersFitIt) {
  ParameterMask candidates{};
  candidates[kRoughness] = candidates[kSheen] = true;
  ParameterVector held = DefaultParameters();
  held[kSpecular] = 0.5;
  held[kSpecularTint] = 0.2;  // a held tint is not reset to the grid's 0 either
  int evaluations = 0;
  const ParameterVector start = GridStart(candidates, held, /*search_sheen=*/true, [&](const ParameterVector& p) {
    ++evaluations;
    EXPECT_DOUBLE_EQ(p[kSpecular], 0.5);
    EXPECT_DOUBLE_EQ(p[kSpecularTint], 0.2);
    return ValleyCost(p);
  });
  EXPECT_EQ(evaluations, 11 * 4) << "roughness x sheen grid only";
  EXPECT_DOUBLE_EQ(start[kSpecular], 0.5);
  // Peak 0.5 / r^2 closest to 0.25 / 0.09 on the grid: r = 0.4 (3.125), not the free optimum 0.3.
  EXPECT_DOUBLE_EQ(start[kRoughness], 0.4);
}

// The broad start of a refit whose roughness hid a held lobe in a spike (cluster_fit.cc): roughness
// grid points below `min_roughness` are not tried; a held roughness keeps its value whatever it is.
TEST(GridStart, AMinimumRoughnessSkipsTheGridPointsBelowIt) {
  ParameterMask candidates{};
  candidates[kRoughness] = candidates[kSheen] = true;
  ParameterVector held = DefaultParameters();
  held[kSpecular] = 0.5;
  int evaluations = 0;
  const ParameterVector start = GridStart(
      candidates, held, /*search_sheen=*/true,
      [&](const ParameterVector& p) {
        ++evaluations;
        EXPECT_GE(p[kRoughness], 0.5);
        return ValleyCost(p);
      },
      /*min_roughness=*/0.5);
  EXPECT_EQ(evaluations, 5 * 4) << "roughness 0.5, 0.6, 0.7, 0.85, 1 x the sheen grid";
  // The best of those: 0.5 (peak 0.5 / 0.25 = 2 against 0.25 / 0.09), not the grid's 0.4.
  EXPECT_DOUBLE_EQ(start[kRoughness], 0.5);
  candidates[kRoughness] = false;
  held[kRoughness] = 0.1;
  const ParameterVector held_roughness = GridStart(candidates, held, /*search_sheen=*/true, ValleyCost, 0.5);
  EXPECT_DOUBLE_EQ(held_roughness[kRoughness], 0.1);
}

}  // namespace
}  // namespace u3mscan::fitting
