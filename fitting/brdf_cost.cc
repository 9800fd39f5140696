// The only translation unit that instantiates the core BRDF on ceres::Jet: automatic
// differentiation compiles slowly, so every templated evaluation of the fitter lives here.
#include "fitting/brdf_cost.h"

#include <ceres/autodiff_cost_function.h>
#include <ceres/jet.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>

#include "core/principled_brdf.h"

namespace u3mscan::fitting {
namespace {

// Smallest luminance the luminance passes use: a black pixel gives the core's white tint anyway.
constexpr double kMinLuminance = 1e-6;
// Guards a weighted normal equation whose diagonal vanishes (no diffuse signal at all).
constexpr double kTinyNormal = 1e-300;
// A secant step is taken only when the slope estimate is not lost in rounding.
constexpr double kTinySecant = 1e-12;
// Step (radians, ~0.06 deg) of the normal-tilt differences: the BRDF is smooth over it except at a
// horizon, where a one-sided kink costs O(step) in one derivative of one observation.
constexpr double kNormalTiltStepRad = 1e-3;
// Below this squared residual the Cauchy factor is 1 to rounding; avoids 0/0.
constexpr double kTinySquaredResidual = 1e-20;

template <typename T>
PrincipledParams<T> ToPrincipled(const T* p, const Vec3<T>& base_color) {
  PrincipledParams<T> out;
  out.base_color = base_color;
  out.roughness = p[static_cast<int>(FitParameter::kRoughness)];
  out.specular = p[static_cast<int>(FitParameter::kSpecular)];
  out.specular_tint = p[static_cast<int>(FitParameter::kSpecularTint)];
  out.sheen = p[static_cast<int>(FitParameter::kSheen)];
  out.sheen_tint = p[static_cast<int>(FitParameter::kSheenTint)];
  out.anisotropic = p[static_cast<int>(FitParameter::kAnisotropic)];
  out.metallic = p[static_cast<int>(FitParameter::kMetallic)];
  // Fabric: no clearcoat, no subsurface term (the core defaults clearcoat_gloss only matter when
  // clearcoat > 0).
  out.subsurface = T(0);
  out.clearcoat = T(0);
  return out;
}

// Factor that turns a residual of squared norm `sq` into one of squared norm rho(sq).
template <typename T>
T RobustFactor(const T& sq, const RobustLoss& loss) {
  using std::log1p;
  using std::sqrt;
  const double a = loss.scale;
  switch (loss.kind) {
    case RobustLossKind::kNone:
      return T(1);
    case RobustLossKind::kHuber:
      // rho(s) = s for s <= a^2, 2 a sqrt(s) - a^2 beyond.
      if (sq > T(a * a)) {
        const T norm = sqrt(sq);
        return sqrt(T(2 * a) * norm - T(a * a)) / norm;
      }
      return T(1);
    case RobustLossKind::kCauchy:
      // rho(s) = a^2 log(1 + s / a^2), by log1p: log(1 + x) is exactly 0 for x below the double
      // epsilon, which made the factor 0 and its derivative (sqrt at 0) infinite for a residual a
      // hair from the data (noise-free renders: Ceres rejected those evaluations).
      if (sq > T(kTinySquaredResidual)) return T(a) * sqrt(log1p(sq / T(a * a)) / sq);
      return T(1);
  }
  return T(1);
}

// Core of the cost for any scalar type. `scratch` holds 5 values per observation: the run's A_o and
// s_o, then the entry's colour parts (EvaluatePrincipledColourParts) times its cos_l E share.
template <typename T>
Vec3<T> PixelResidualsT(const T* p, std::span<const LocalObservation> observations, const PixelCostSettings& settings,
                        T* residuals, std::vector<T>& scratch) {
  using std::abs;
  const std::size_t n = observations.size();
  scratch.resize(5 * n);
  T* parts = scratch.data() + 2 * n;
  // The lobes once per entry: the passes below only weigh them by the luminance. Per unit base
  // colour C of luminance l the tint is C / l, so an entry predicts C (per_colour + per_tint / l)
  // + white: linear in C once l is fixed.
  const PrincipledParams<T> params = ToPrincipled(p, Vec3<T>(Vec3<T>::Zero()));  // the colour is not read
  for (std::size_t i = 0; i < n; ++i) {
    const LocalObservation& o = observations[i];
    const PrincipledColourParts<T> f =
        EvaluatePrincipledColourParts(params, Vec3<T>(o.light_local.cast<T>()), Vec3<T>(o.view_local.cast<T>()));
    const double geometry = o.light_local.z() * o.irradiance * o.facet_weight;  // cos_l * E * share
    parts[3 * i] = f.per_colour * geometry;
    parts[3 * i + 1] = f.per_tint * geometry;
    parts[3 * i + 2] = f.white * geometry;
  }
  T luminance = T(std::max(settings.luminance_start, kMinLuminance));
  Vec3<T> color = Vec3<T>::Zero();
  const int passes = std::max(1, settings.luminance_passes);
  // Fixed point l = lum(C(l)) by the secant method on h(l) = lum(C(l)) - l (plain substitution
  // for the second pass): converges superlinearly, where substitution alone contracts only by the
  // ratio of tinted to diffuse signal per pass.
  T previous_luminance = luminance;
  T previous_h = T(0);
  for (int pass = 0; pass < passes; ++pass) {
    if (pass > 0) {
      const T g = brdf::TintLuminance(color);
      const T h = g - luminance;
      T next = g;
      if (pass > 1) {
        const T dh = h - previous_h;
        if (abs(dh) > T(kTinySecant) * abs(h) + T(kTinyNormal)) next = luminance - h * (luminance - previous_luminance) / dh;
      }
      previous_luminance = luminance;
      previous_h = h;
      luminance = next < T(kMinLuminance) ? T(kMinLuminance) : next;
    }
    const T inverse_luminance = T(1) / luminance;
    T num[3] = {T(0), T(0), T(0)};
    T den[3] = {T(0), T(0), T(0)};
    // A facet run's A and s are the sums over its entries (the model is linear in C per entry).
    T run_a = T(0), run_s = T(0);
    for (std::size_t i = 0; i < n; ++i) {
      const LocalObservation& o = observations[i];
      run_a += parts[3 * i] + parts[3 * i + 1] * inverse_luminance;
      run_s += parts[3 * i + 2];
      if (o.continues) {  // no data here: residual slots 0
        scratch[2 * i] = T(0);
        scratch[2 * i + 1] = T(0);
        continue;
      }
      const T a = run_a;
      const T s = run_s;
      run_a = T(0);
      run_s = T(0);
      scratch[2 * i] = a;
      scratch[2 * i + 1] = s;
      for (int c = 0; c < 3; ++c) {
        const double w2 = o.weight(c) * o.weight(c);
        num[c] += w2 * a * (T(o.rgb(c)) - s);
        den[c] += w2 * a * a;
      }
    }
    for (int c = 0; c < 3; ++c) {
      color(c) = den[c] > T(kTinyNormal) ? num[c] / den[c] : T(0);
    }
  }
  if (residuals != nullptr) {
    for (std::size_t i = 0; i < n; ++i) {
      const LocalObservation& o = observations[i];
      const T& a = scratch[2 * i];
      const T& s = scratch[2 * i + 1];
      T r[3];
      for (int c = 0; c < 3; ++c) r[c] = (a * color(c) + s - T(o.rgb(c))) * o.weight(c);
      const T factor = RobustFactor(r[0] * r[0] + r[1] * r[1] + r[2] * r[2], settings.loss);
      for (int c = 0; c < 3; ++c) residuals[3 * i + c] = r[c] * factor;
    }
  }
  return color;
}

struct PixelFunctor {
  std::span<const LocalObservation> observations;
  PixelCostSettings settings;

  template <typename T>
  bool operator()(const T* roughness, const T* specular, const T* specular_tint, const T* sheen,
                  const T* sheen_tint, const T* anisotropic, const T* metallic, T* residuals) const {
    const T p[kFitParameterCount] = {*roughness, *specular, *specular_tint, *sheen,
                                     *sheen_tint, *anisotropic, *metallic};
    // One per thread and scalar type: an evaluation does not allocate once the largest pixel has
    // been seen.
    thread_local std::vector<T> scratch;
    PixelResidualsT<T>(p, observations, settings, residuals, scratch);
    return true;
  }
};

using PixelAutoDiff = ceres::AutoDiffCostFunction<PixelFunctor, ceres::DYNAMIC, 1, 1, 1, 1, 1, 1, 1>;

}  // namespace

const char* FitParameterName(FitParameter parameter) {
  switch (parameter) {
    case FitParameter::kRoughness: return "roughness";
    case FitParameter::kSpecular: return "specular";
    case FitParameter::kSpecularTint: return "specular_tint";
    case FitParameter::kSheen: return "sheen";
    case FitParameter::kSheenTint: return "sheen_tint";
    case FitParameter::kAnisotropic: return "anisotropic";
    case FitParameter::kMetallic: return "metallic";
  }
  throw std::logic_error("FitParameterName: unknown parameter");
}

double FitParameterDefault(FitParameter parameter) {
  // docs/u3m-conventions.md: roughness 0.7, specular 0.5, metalness, sheen and tints 0.
  switch (parameter) {
    case FitParameter::kRoughness: return 0.7;
    case FitParameter::kSpecular: return 0.5;
    default: return 0.0;
  }
}

ParameterVector DefaultParameters() {
  ParameterVector out{};
  for (int i = 0; i < kFitParameterCount; ++i) out[i] = FitParameterDefault(static_cast<FitParameter>(i));
  return out;
}

int LuminancePassesFor(const ParameterVector& params, const ParameterMask& free, int tinted_passes) {
  const int st = static_cast<int>(FitParameter::kSpecularTint);
  const int sht = static_cast<int>(FitParameter::kSheenTint);
  const bool tinted = free[st] || free[sht] || params[st] != 0.0 || params[sht] != 0.0;
  return tinted ? std::max(1, tinted_passes) : 1;
}

Eigen::Vector3d SolveBaseColor(const ParameterVector& params, std::span<const LocalObservation> observations,
                               const PixelCostSettings& settings) {
  thread_local std::vector<double> scratch;
  return PixelResidualsT<double>(params.data(), observations, settings, nullptr, scratch);
}

double PixelResiduals(const ParameterVector& params, std::span<const LocalObservation> observations,
                      const PixelCostSettings& settings, double* residuals, Eigen::Vector3d* base_color) {
  thread_local std::vector<double> scratch;
  const Eigen::Vector3d color = PixelResidualsT<double>(params.data(), observations, settings, residuals, scratch);
  if (base_color != nullptr) *base_color = color;
  double cost = 0.0;
  for (std::size_t i = 0; i < 3 * observations.size(); ++i) cost += residuals[i] * residuals[i];
  return 0.5 * cost;
}

ceres::CostFunction* MakePixelCostFunction(std::span<const LocalObservation> observations,
                                           const PixelCostSettings& settings) {
  if (observations.empty()) throw std::invalid_argument("MakePixelCostFunction: no observations");
  return new PixelAutoDiff(new PixelFunctor{observations, settings}, static_cast<int>(3 * observations.size()));
}

bool EvaluatePixelJacobian(const ParameterVector& params, std::span<const LocalObservation> observations,
                           const PixelCostSettings& settings, Eigen::VectorXd* residuals,
                           Eigen::MatrixXd* jacobian) {
  const std::unique_ptr<ceres::CostFunction> cost(MakePixelCostFunction(observations, settings));
  const int m = static_cast<int>(3 * observations.size());
  residuals->resize(m);
  // One column per parameter block of size 1; Eigen's default column-major storage makes each
  // column a contiguous m-vector, which is the row-major m x 1 block Ceres writes.
  jacobian->resize(m, kFitParameterCount);
  const double* parameter_blocks[kFitParameterCount];
  double* jacobian_blocks[kFitParameterCount];
  for (int i = 0; i < kFitParameterCount; ++i) {
    parameter_blocks[i] = &params[i];
    jacobian_blocks[i] = jacobian->col(i).data();
  }
  return cost->Evaluate(parameter_blocks, residuals->data(), jacobian_blocks);
}

bool EvaluateNormalTiltJacobian(const ParameterVector& params, std::span<const LocalObservation> observations,
                                const PixelCostSettings& settings, std::vector<LocalObservation>& scratch,
                                Eigen::MatrixXd* jacobian) {
  const std::size_t n = observations.size();
  const int m = static_cast<int>(3 * n);
  jacobian->resize(m, 2);
  scratch.resize(n);
  thread_local std::vector<double> plus, minus;
  plus.resize(m);
  minus.resize(m);
  for (int axis = 0; axis < 2; ++axis) {
    for (const double sign : {1.0, -1.0}) {
      // Tilting the normal by +a about a local axis is seeing every direction turned by -a about it.
      const double angle = -sign * kNormalTiltStepRad;
      const Eigen::Matrix3d turn =
          Eigen::AngleAxisd(angle, axis == 0 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY()).toRotationMatrix();
      for (std::size_t o = 0; o < n; ++o) {
        scratch[o] = observations[o];
        scratch[o].light_local = turn * observations[o].light_local;
        scratch[o].view_local = turn * observations[o].view_local;
      }
      PixelResiduals(params, scratch, settings, sign > 0 ? plus.data() : minus.data());
    }
    for (int r = 0; r < m; ++r) (*jacobian)(r, axis) = (plus[r] - minus[r]) / (2.0 * kNormalTiltStepRad);
  }
  return jacobian->allFinite();
}

int CountMeasurements(std::span<const LocalObservation> observations) {
  return static_cast<int>(std::count_if(observations.begin(), observations.end(),
                                        [](const LocalObservation& o) { return !o.continues; }));
}

Eigen::Vector3d RenderRun(const ParameterVector& params, const Eigen::Vector3d& base_color,
                          std::span<const LocalObservation> observations, std::size_t begin, std::size_t* end) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  std::size_t i = begin;
  for (; i < observations.size(); ++i) {
    const LocalObservation& o = observations[i];
    sum += o.facet_weight * RenderLocal(params, base_color, o.light_local, o.view_local, o.irradiance);
    if (!o.continues) break;
  }
  *end = std::min(i + 1, observations.size());
  return sum;
}

Eigen::Vector3d RenderLocal(const ParameterVector& params, const Eigen::Vector3d& base_color,
                            const Eigen::Vector3d& light_local, const Eigen::Vector3d& view_local,
                            double irradiance) {
  const PrincipledParams<double> p = ToPrincipled(params.data(), Vec3<double>(base_color));
  const Vec3<double> f = EvaluatePrincipled(p, Vec3<double>(light_local), Vec3<double>(view_local));
  return f * (std::max(0.0, light_local.z()) * irradiance);
}

double GrazingWeight(const LocalObservation& observation) {
  Eigen::Vector3d h = observation.light_local + observation.view_local;
  const double len = h.norm();
  if (len < brdf::kTinyLength) return 0.0;
  h /= len;
  return brdf::SchlickWeight(observation.light_local.dot(h));
}

}  // namespace u3mscan::fitting
