#pragma once
// Robust weight functions for iteratively reweighted least squares (IRLS), shared by photometric
// stereo (per-observation weights) and normal integration (per-edge weights).

#include <cmath>

namespace u3mscan::reconstruction {

enum class RobustLoss {
  kCauchy,  // w = 1 / (1 + u^2): every observation keeps some weight; convex-like, stable
  kTukey,   // biweight w = (1 - u^2)^2 for |u| < 1, else 0: rejects gross outliers completely
};

// Tuning constants that give 95 % efficiency under Gaussian noise (Holland and Welsch 1977),
// in units of the residual scale sigma.
inline constexpr double kCauchyTuning = 2.385;
inline constexpr double kTukeyTuning = 4.685;

inline double RobustTuning(RobustLoss loss) { return loss == RobustLoss::kCauchy ? kCauchyTuning : kTukeyTuning; }

// IRLS weight of a residual r with residual scale sigma (> 0).
inline double RobustWeight(RobustLoss loss, double r, double sigma) {
  const double u = r / (RobustTuning(loss) * sigma);
  const double u2 = u * u;
  if (loss == RobustLoss::kCauchy) return 1.0 / (1.0 + u2);
  if (u2 >= 1.0) return 0.0;
  const double t = 1.0 - u2;
  return t * t;
}

// 1.4826 * median absolute deviation estimates sigma of Gaussian noise.
inline constexpr double kMadToSigma = 1.4826;

// sigma of Gaussian noise from the q-quantile of |residual| (q = 0.5: the MAD rule): 1 / (sqrt(2)
// erfinv(q)). A lower q looks only at the best-fitting observations, so a large share of outliers
// (shadows plus highlights) does not inflate the scale.
double QuantileToSigma(double q);

}  // namespace u3mscan::reconstruction
