#pragma once
// The fitting cost: residuals of one pixel's observations against the core Principled BRDF
// (core/principled_brdf.h, the same code the renderer uses), with the pixel's base colour solved in
// closed form inside the non-linear fit (variable projection) and a robust loss per observation.
//
// Model of one observation o of a pixel (Stack contract, core/stack.h):
//   rgb_o = f(L_o, V_o; params, C) * cos_l * E_o
// with L, V unit vectors in the pixel's local shading frame (z = normal, x = world +x projected into
// the tangent plane, the direction of anisotropy), E_o the relative irradiance (before the cosine)
// and C the linear-RGB base colour.
//
// Base colour in closed form: for a fixed luminance l of C, every lobe of the model is linear in C
// (the tints use C / l): f(C) = A(l) C + s(l) (1,1,1) with scalars A and s per observation. One BRDF
// evaluation with the probe colour (l / 0.3, 0, 0) (luminance l) gives both: its red channel is
// A l / 0.3 + s, its green channel s. C then follows per channel by weighted linear least squares;
// when a tint (specular_tint, sheen_tint) is in play, l = lum(C) is found by a few passes of a
// secant iteration on l - lum(C(l)). With specular_tint = sheen_tint = 0 the model is linear in C and one pass is exact.
//
// Residuals: 3 per observation (linear RGB), each (prediction - measurement) * weight, weight =
// 1 / sigma of the noise model (set by the caller). The robust loss rho is applied per observation
// (the light block of 3 channels) inside the residual: r' = r sqrt(rho(|r|^2)) / |r|, so that
// |r'|^2 = rho(|r|^2) and the solver minimises sum_o rho(|r_o|^2) exactly.

#include <Eigen/Core>
#include <array>
#include <span>
#include <string>
#include <vector>

namespace ceres {
class CostFunction;
}

namespace u3mscan::fitting {

// The Principled parameters the fitter can estimate. Base colour is per pixel and solved in closed
// form, so it is not in this list.
enum class FitParameter : int {
  kRoughness = 0,
  kSpecular,
  kSpecularTint,
  kSheen,
  kSheenTint,
  kAnisotropic,
  kMetallic,
};
inline constexpr int kFitParameterCount = 7;
// Each parameter's position in a ParameterVector, a ParameterMask and ClusterFit::parameters.
inline constexpr int kRoughness = static_cast<int>(FitParameter::kRoughness);
inline constexpr int kSpecular = static_cast<int>(FitParameter::kSpecular);
inline constexpr int kSpecularTint = static_cast<int>(FitParameter::kSpecularTint);
inline constexpr int kSheen = static_cast<int>(FitParameter::kSheen);
inline constexpr int kSheenTint = static_cast<int>(FitParameter::kSheenTint);
inline constexpr int kAnisotropic = static_cast<int>(FitParameter::kAnisotropic);
inline constexpr int kMetallic = static_cast<int>(FitParameter::kMetallic);

using ParameterVector = std::array<double, kFitParameterCount>;
using ParameterMask = std::array<bool, kFitParameterCount>;

// Snake-case name as in U3M docs and fit.json ("roughness", "sheen_tint", ...).
const char* FitParameterName(FitParameter parameter);
inline const char* FitParameterName(int index) { return FitParameterName(static_cast<FitParameter>(index)); }
// The U3M 1.0 default of the parameter (roughness 0.7, specular 0.5, every other one 0): what a
// parameter the capture does not constrain is written as.
double FitParameterDefault(FitParameter parameter);
ParameterVector DefaultParameters();

// One usable observation of one pixel, already in the pixel's local shading frame. Fixed size, so
// per-pixel work can reuse one buffer per worker instead of allocating.
//
// Facet runs (fitting/facet_mixture.h): an observation of a pixel that holds several facets is a
// run of consecutive entries, one per facet, each with the light and view turned into that
// facet's frame (the pixel's frame turned by the facet's tilt) and its share `facet_weight`. Every
// entry of the run but the last has `continues` set and carries no data (rgb and weight 0); the
// last carries the measurement. The cost predicts the run as sum over its entries of facet_weight *
// f * cos_l * E and forms its residual at the last entry; the continued entries keep their three
// residual slots, always 0, so that every count of residuals stays 3 per entry.
struct LocalObservation {
  Eigen::Vector3d light_local = Eigen::Vector3d::UnitZ();  // unit, toward the light, z = normal
  Eigen::Vector3d view_local = Eigen::Vector3d::UnitZ();   // unit, toward the camera
  double irradiance = 1.0;                                 // relative irradiance before the cosine
  Eigen::Vector3d rgb = Eigen::Vector3d::Zero();           // measurement, linear RGB
  Eigen::Vector3d weight = Eigen::Vector3d::Ones();        // 1 / sigma per channel
  double facet_weight = 1.0;  // share of the prediction of its run (1: a plain observation)
  bool continues = false;     // the next entry belongs to the same observation (a facet run)
};

// Number of measurements among `observations` (entries that end a run, see LocalObservation).
int CountMeasurements(std::span<const LocalObservation> observations);

enum class RobustLossKind { kNone, kHuber, kCauchy };

// Robust loss on the squared norm s of one observation's weighted RGB residual. `scale` is in units
// of sigma: observations within `scale` sigma count quadratically.
struct RobustLoss {
  RobustLossKind kind = RobustLossKind::kHuber;
  double scale = 3.0;
};

// How one pixel's residuals are formed.
struct PixelCostSettings {
  RobustLoss loss;
  // Luminance of the base colour to start the luminance passes from (any positive guess).
  double luminance_start = 0.2;
  // Passes (base-colour solves) for l = lum(C); 1 is exact when no tint is in play.
  int luminance_passes = 1;
};

// Number of luminance passes needed for the given parameters: 1 when both tints are held at 0,
// `tinted_passes` otherwise.
int LuminancePassesFor(const ParameterVector& params, const ParameterMask& free, int tinted_passes);

// Closed-form base colour of a pixel for the given shared parameters (weighted least squares per
// channel). Not clamped: callers clamp for output.
Eigen::Vector3d SolveBaseColor(const ParameterVector& params, std::span<const LocalObservation> observations,
                               const PixelCostSettings& settings);

// Residuals (3 per observation, robustified) for the given parameters, the base colour solved in
// closed form. `residuals` must hold 3 * observations.size() values. Returns 0.5 * sum of squares
// (the Ceres cost) and the solved colour in *base_color when non-null.
double PixelResiduals(const ParameterVector& params, std::span<const LocalObservation> observations,
                      const PixelCostSettings& settings, double* residuals, Eigen::Vector3d* base_color = nullptr);

// The same residuals as a Ceres cost function (automatic differentiation through the core BRDF):
// seven parameter blocks of size 1 in FitParameter order. The observations are referenced, not
// copied: they must outlive the cost function.
ceres::CostFunction* MakePixelCostFunction(std::span<const LocalObservation> observations,
                                           const PixelCostSettings& settings);

// Residuals and their Jacobian (3n x 7, column per FitParameter) from the automatic-differentiation
// cost. For observability and tests. Returns false if Ceres reports failure.
bool EvaluatePixelJacobian(const ParameterVector& params, std::span<const LocalObservation> observations,
                           const PixelCostSettings& settings, Eigen::VectorXd* residuals,
                           Eigen::MatrixXd* jacobian);

// Jacobian (3n x 2) of the same residuals with respect to two tilts of the pixel's normal, in
// radians about the local x and y axes (central differences; the base colour is solved again at
// each step, as in the residuals). For observability: a lobe that a small tilt of the normal can
// imitate is not measured by the pixel. `scratch` is resized to n and reused (no allocation once
// it is large enough).
bool EvaluateNormalTiltJacobian(const ParameterVector& params, std::span<const LocalObservation> observations,
                                const PixelCostSettings& settings, std::vector<LocalObservation>& scratch,
                                Eigen::MatrixXd* jacobian);

// Rendered value of one entry: f * cos_l * E in linear RGB (0 below either horizon), facet_weight
// not applied. RenderRun sums a whole run (a plain observation alone): facet_weight times RenderLocal
// over its entries, starting at `observations[begin]`; `*end` gets the index past the run.
Eigen::Vector3d RenderRun(const ParameterVector& params, const Eigen::Vector3d& base_color,
                          std::span<const LocalObservation> observations, std::size_t begin, std::size_t* end);
Eigen::Vector3d RenderLocal(const ParameterVector& params, const Eigen::Vector3d& base_color,
                            const Eigen::Vector3d& light_local, const Eigen::Vector3d& view_local,
                            double irradiance);

// The Schlick weight (1 - cos_d)^5 of an observation: how strongly sheen and Fresnel act on it.
double GrazingWeight(const LocalObservation& observation);

}  // namespace u3mscan::fitting
