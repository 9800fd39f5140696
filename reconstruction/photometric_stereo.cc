#include "reconstruction/photometric_stereo.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <vector>

#include "core/logging.h"
#include "core/parallel.h"

namespace u3mscan::reconstruction {

std::string PsSolverName(PsSolver solver) { return solver == PsSolver::kLeastSquares ? "ls" : "robust"; }

PsSolver ParsePsSolver(const std::string& name) {
  if (name == "ls") return PsSolver::kLeastSquares;
  if (name == "robust") return PsSolver::kRobust;
  throw std::invalid_argument("solver must be ls or robust, got '" + name + "'");
}

double QuantileToSigma(double q) {
  // Inverse of erf by bisection: called once per pixel iteration with the same q, so cache it.
  static thread_local double cached_q = -1.0, cached_factor = 0.0;
  if (q == cached_q) return cached_factor;
  double lo = 0.0, hi = 6.0;
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    (std::erf(mid) < q ? lo : hi) = mid;
  }
  cached_q = q;
  cached_factor = 1.0 / (std::sqrt(2.0) * 0.5 * (lo + hi));
  return cached_factor;
}

std::string DiffuseModelName(DiffuseModel model) { return model == DiffuseModel::kLambert ? "lambert" : "burley"; }

DiffuseModel ParseDiffuseModel(const std::string& name) {
  if (name == "lambert") return DiffuseModel::kLambert;
  if (name == "burley") return DiffuseModel::kBurley;
  throw std::invalid_argument("diffuse model must be lambert or burley, got '" + name + "'");
}

bool PhotometricStereoOptions::Check() const {
  return view >= -1 && diffuse_roughness <= 1.0 && diffuse_iterations >= 0 && dark_shading >= 0.0 && band_low_fraction >= 0.0 && band_high_fraction >= 0.0 &&
         band_low_fraction + band_high_fraction < 1.0 && residual_quantile > 0.0 && residual_quantile < 1.0 && irls_iterations >= 0 && min_residual_fraction > 0.0 &&
         good_condition >= 1.0 && max_condition > good_condition && max_reported_condition >= max_condition &&
         reliable_albedo > 0.0 && min_normal_z > 0.0 && min_normal_z < 1.0 && residual_tolerance > 0.0 &&
         regularisation > 0.0 && regularise_below_confidence >= 0.0 && regularise_below_confidence <= 1.0 &&
         max_near_iterations >= 0 && near_tolerance_deg > 0.0 && integration.Check();
}

namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;

// Albedo values are clamped to this (a physical reflectance is <= 1; anything near this bound
// comes from broken input such as a near-zero measured irradiance).
constexpr double kMaxAlbedo = 1e6;

// Smallest cosine the albedo of a regularised pixel assumes for its observations (84 deg).
constexpr double kRegularisedCosFloor = 0.1;

double SchlickWeight(double c) {
  const double m = std::clamp(1.0 - c, 0.0, 1.0);
  const double m2 = m * m;
  return m2 * m2 * m;
}

// Per-pixel state bits, counted into the result after the parallel passes.
enum PixelState : std::uint8_t {
  kDark = 1u << 0,
  kIllConditioned = 1u << 1,
  kLowAlbedo = 1u << 2,
  kClamped = 1u << 3,
  kRegularised = 1u << 4,
  kLowConfidence = 1u << 5,  // pass-1 confidence below regularise_below_confidence
  kSecondPass = 1u << 6,     // solved again in pass 2, with its neighbours' normal at hand
};
// Pixels whose first-pass estimate is not to be trusted alone: re-solved with the neighbour prior.
constexpr std::uint8_t kNeedsNeighbours = kDark | kIllConditioned | kLowAlbedo | kLowConfidence;

// One observation at the current pixel. Lives in a per-chunk scratch array: no per-pixel allocation.
struct PixelObservation {
  Vector3d s;           // E * l, light vector scaled by relative irradiance
  Vector3d l;           // unit direction toward the light
  Vector3d v;           // unit direction toward the camera
  Vector3d raw_rgb;     // observed linear RGB
  Vector3d rgb;         // raw_rgb divided by the diffuse lobe's factor (kBurley), else raw_rgb
  double fd90_minus_1 = 0.0;  // kBurley: fd90 - 1 of this light and view (independent of the normal)
  double grey = 0.0;    // mean of rgb
  double inv_e = 0.0;   // 1 / E: residuals * inv_e are in shading units (rho / pi * cos)
  double weight = 0.0;  // current IRLS weight (0 = not used)
  double previous_weight = 0.0;  // of the last accepted IRLS round
  bool candidate = false;
};

struct Scratch {
  std::vector<PixelObservation> obs;
  std::vector<double> values;    // for medians
  std::vector<double> per_obs;   // one value per observation: band keys, then IRLS residuals
  std::vector<int> order;        // for band selection
  explicit Scratch(std::size_t k) : obs(k), values(k), per_obs(k), order(k) {}
};

// B = A^-1 R for the 3x3 normal equations A (symmetric, positive semi-definite by construction)
// in closed form (cofactors: no factorisation, no triangular solves); false, B untouched, when A
// is too close to singular: det(A) <= 1e-12 trace(A)^3 (fewer than 3 independent lights).
bool SolveNormalEquations(const Matrix3d& a, const Matrix3d& r, Matrix3d* b) {
  // One pass of cofactors gives both the determinant and the inverse (threshold 0: the test on
  // det is ours, below).
  Matrix3d inverse;
  double det = 0.0;
  bool invertible = false;
  a.computeInverseAndDetWithCheck(inverse, det, invertible, 0.0);
  const double scale = a.trace();
  if (!invertible || !(det > 1e-12 * scale * scale * scale)) return false;
  *b = inverse * r;
  return true;
}

// The weighted normal equations of one pixel and their eigen-decomposition.
struct PixelSystem {
  Matrix3d a = Matrix3d::Zero();  // sum w s s^T
  Matrix3d r = Matrix3d::Zero();  // sum w s rgb^T (one column per channel)
  Vector3d eigenvalues = Vector3d::Zero();
  Matrix3d eigenvectors = Matrix3d::Identity();
  double weight_sum = 0.0;

  // decompose = false skips the eigen-decomposition (IRLS rounds solve in closed form,
  // SolveNormalEquations; only the final system needs eigenvalues for the condition number and the pseudo-inverse).
  // The sums are kept in scalars, A's upper triangle only (it is symmetric): an IRLS round
  // rebuilds this system, and the rounds are most of photometric stereo's time.
  void Build(const std::vector<PixelObservation>& obs, bool decompose = true) {
    double a00 = 0.0, a01 = 0.0, a02 = 0.0, a11 = 0.0, a12 = 0.0, a22 = 0.0;
    r.setZero();
    weight_sum = 0.0;
    for (const PixelObservation& o : obs) {
      if (o.weight <= 0.0) continue;
      const Vector3d ws = o.weight * o.s;
      a00 += ws.x() * o.s.x();
      a01 += ws.x() * o.s.y();
      a02 += ws.x() * o.s.z();
      a11 += ws.y() * o.s.y();
      a12 += ws.y() * o.s.z();
      a22 += ws.z() * o.s.z();
      r.noalias() += ws * o.rgb.transpose();
      weight_sum += o.weight;
    }
    a << a00, a01, a02, a01, a11, a12, a02, a12, a22;
    if (decompose) Decompose();
  }

  void Decompose() {
    Eigen::SelfAdjointEigenSolver<Matrix3d> es;
    es.computeDirect(a);
    eigenvalues = es.eigenvalues().cwiseMax(0.0);  // ascending
    eigenvectors = es.eigenvectors();
  }

  double Condition(double cap) const {
    const double lmax = eigenvalues(2), lmin = eigenvalues(0);
    if (!(lmax > 0.0)) return cap;
    if (!(lmin > 0.0)) return cap;
    return std::min(cap, std::sqrt(lmax / lmin));
  }

  // Solves (A + lambda I) B = R + lambda * prior (prior: 3x3, one column per channel); eigenvalues
  // below 1e-12 lambda_max are treated as zero (pseudo-inverse) so B is always finite.
  Matrix3d Solve(double lambda = 0.0, const Matrix3d& prior = Matrix3d::Zero()) const {
    const double floor = 1e-12 * std::max(eigenvalues(2), 1e-300);
    Matrix3d rhs = eigenvectors.transpose() * (r + lambda * prior);
    for (int i = 0; i < 3; ++i) {
      const double l = eigenvalues(i) + lambda;
      rhs.row(i) = l > floor ? Eigen::RowVector3d(rhs.row(i) / l) : Eigen::RowVector3d::Zero();
    }
    return eigenvectors * rhs;
  }
};

double Quantile(std::vector<double>& values, std::size_t count, double q) {
  if (count == 0) return 0.0;
  auto mid = values.begin() + static_cast<std::size_t>(q * (count - 1) + 0.5);
  std::nth_element(values.begin(), mid, values.begin() + count);
  return *mid;
}

// What the first pass leaves per pixel for the second.
struct PixelEstimate {
  Vector3d normal = Vector3d::UnitZ();
  double condition = 0.0;
  double confidence = 0.0;
  int used = 0;
  std::uint8_t state = 0;
};

// Lights lower than this (sin of 15 deg elevation) keep Lambert's law: at grazing incidence the
// lobe's Schlick term is largest and least supported by real fabrics, and a rig of grazing lights
// alone cannot pin the roughness (cast shadows dominate the residual: the scanner's `grazing` rig,
// 5 deg, picked r = 0 and sent the fitter's roughness to 0.19 for a truth of 0.6).
constexpr double kBurleyMinLightZ = 0.2588;

class Solver {
 public:
  Solver(const Stack& stack, const PhotometricStereoOptions& options) : stack_(stack), options_(options) {
    for (std::size_t k = 0; k < stack.observations.size(); ++k)
      if (options.view < 0 || stack.observations[k].view == options.view) selected_.push_back(static_cast<int>(k));
    for (int k : selected_)
      if (stack.lights[stack.observations[k].light].type == LightType::kPoint) has_point_lights_ = true;
  }

  bool has_point_lights() const { return has_point_lights_; }
  // The diffuse lobe the next Gather uses: Burley's with roughness r, or Lambert's (r < 0).
  void set_roughness(double r) { roughness_ = r; }
  double roughness() const { return roughness_; }
  bool burley() const { return options_.diffuse_model == DiffuseModel::kBurley && roughness_ >= 0.0; }

  // kBurley: divides every observation by the diffuse lobe's factor at normal n, relative to
  // Lambert's law: (1 + (fd90 - 1) SW(n.l)) (1 + (fd90 - 1) SW(n.v)).
  void ApplyDiffuseModel(Scratch& scratch, const Vector3d& n) const {
    for (PixelObservation& o : scratch.obs) {
      if (!o.candidate) continue;
      const double fl = 1.0 + o.fd90_minus_1 * SchlickWeight(std::max(0.0, n.dot(o.l)));
      const double fv = 1.0 + o.fd90_minus_1 * SchlickWeight(std::max(0.0, n.dot(o.v)));
      const double factor = std::max(fl * fv, 1e-3);  // fd90 >= 0.5: the factor is >= 0.25
      o.rgb = o.raw_rgb / factor;
      o.grey = o.rgb.mean();
    }
  }
  std::size_t observation_count() const { return selected_.size(); }

  // Fills scratch.obs for pixel (r, c) at height_mm and returns the number of observations above
  // the dark level.
  int Gather(int r, int c, double height_mm, Scratch& scratch) const {
    const MetricGrid& g = stack_.grid;
    const std::size_t pix = static_cast<std::size_t>(r) * g.width + c;
    const Vector3d x = g.PixelCentreInWorld(c, r, height_mm);
    int bright = 0;
    for (std::size_t j = 0; j < selected_.size(); ++j) {
      const Observation& ob = stack_.observations[selected_[j]];
      const LightModel& light = stack_.lights[ob.light];
      PixelObservation& o = scratch.obs[j];
      o.candidate = false;
      o.weight = 0.0;
      if (!ob.flags.empty() && ob.flags[pix] != 0) continue;
      double e;
      if (!ob.irradiance.empty()) {
        // Measured on the plane z = 0; the model carries it to the current height.
        e = ob.irradiance.data()[pix];
        if (light.type == LightType::kPoint && height_mm != 0.0) {
          const double e0 = light.RelativeIrradianceAt(g.PixelCentreInWorld(c, r, 0.0));
          e = e0 > 0.0 ? e * light.RelativeIrradianceAt(x) / e0 : 0.0;
        }
      } else {
        e = light.RelativeIrradianceAt(x);
      }
      if (!(e > 0.0) || !std::isfinite(e)) continue;
      const int ch = ob.rgb.channels();
      for (int i = 0; i < 3; ++i) o.rgb(i) = ob.rgb.data()[static_cast<std::size_t>(ch == 3 ? i : 0) * g.width * g.height + pix];
      if (!o.rgb.allFinite()) continue;
      o.raw_rgb = o.rgb;
      o.l = light.DirectionFrom(x);
      o.s = o.l * e;
      o.fd90_minus_1 = 0.0;  // Lambert's law unless the Burley lobe applies below
      if (burley() && o.l.z() >= kBurleyMinLightZ) {
        const Vector3d centre = stack_.views.empty() ? Vector3d(0, 0, 1000) : stack_.views[ob.view].centre_in_world_mm;
        o.v = (centre - x).normalized();
        const double cos_d = std::clamp(o.l.dot((o.l + o.v).normalized()), 0.0, 1.0);
        o.fd90_minus_1 = 2.0 * roughness_ * cos_d * cos_d - 0.5;
      }
      o.inv_e = 1.0 / e;
      o.grey = o.rgb.mean();
      const bool is_bright = o.grey * o.inv_e > options_.dark_shading;
      bright += is_bright;
      // The baseline takes every unflagged observation; the robust solver drops the dark ones.
      o.candidate = options_.solver == PsSolver::kLeastSquares || is_bright;
    }
    return bright;
  }

  // Weights of the candidates (least squares, or band selection + IRLS) and the final system.
  void Weigh(Scratch& scratch, PixelSystem& sys) const {
    auto& obs = scratch.obs;
    const std::size_t k = obs.size();
    if (options_.solver == PsSolver::kLeastSquares) {
      for (auto& o : obs) o.weight = o.candidate ? 1.0 : 0.0;
      sys.Build(obs);
      return;
    }
    // Band selection: sort the candidates by shading, leave out the darkest and brightest.
    std::vector<double>& per_obs = scratch.per_obs;
    int n = 0;
    for (std::size_t j = 0; j < k; ++j) {
      if (!obs[j].candidate) continue;
      per_obs[j] = obs[j].grey * obs[j].inv_e;  // the sort key, computed once
      scratch.order[n++] = static_cast<int>(j);
    }
    std::sort(scratch.order.begin(), scratch.order.begin() + n, [&](int a, int b) { return per_obs[a] < per_obs[b]; });
    int low = static_cast<int>(n * options_.band_low_fraction);
    int high = static_cast<int>(n * options_.band_high_fraction);
    const int keep = std::min(n, 4);
    while (n - low - high < keep && (low > 0 || high > 0)) (low >= high ? low : high)--;
    for (int i = 0; i < n; ++i) obs[scratch.order[i]].weight = (i >= low && i < n - high) ? 1.0 : 0.0;
    sys.Build(obs, /*decompose=*/false);
    Matrix3d b;
    if (!SolveNormalEquations(sys.a, sys.r, &b)) {
      sys.Decompose();
      b = sys.Solve();  // the pseudo-inverse: what a nearly coplanar band constrains
    }
    // IRLS over all candidates from the band estimate.
    for (int it = 0; it < options_.irls_iterations; ++it) {
      const Vector3d bg = b.rowwise().mean();
      const double b_norm = bg.norm();
      if (!(b_norm > 0.0)) break;
      std::size_t m = 0;
      // Residual of an observation: its worst channel, in shading units, so that a clip or a
      // tint in one channel counts in full. -1 marks an attached shadow (the linear model
      // predicts a negative value the camera cannot see) or a non-candidate: weight 0.
      for (std::size_t j = 0; j < k; ++j) {
        const PixelObservation& o = obs[j];
        if (!o.candidate || o.s.dot(bg) <= 0.0) {
          per_obs[j] = -1.0;
          continue;
        }
        per_obs[j] = (o.rgb - b.transpose() * o.s).cwiseAbs().maxCoeff() * o.inv_e;
        scratch.values[m++] = per_obs[j];
      }
      const double sigma = std::max(QuantileToSigma(options_.residual_quantile) * Quantile(scratch.values, m, options_.residual_quantile), options_.min_residual_fraction * b_norm);
      double change = 0.0;
      for (std::size_t j = 0; j < k; ++j) {
        PixelObservation& o = obs[j];
        const double w = per_obs[j] >= 0.0 ? RobustWeight(options_.loss, per_obs[j], sigma) : 0.0;
        change = std::max(change, std::fabs(w - o.weight));
        o.previous_weight = o.weight;
        o.weight = w;
      }
      PixelSystem next;
      next.Build(obs, /*decompose=*/false);
      // Weights left fewer than 3 independent lights: keep the last good system.
      if (!SolveNormalEquations(next.a, next.r, &b)) {
        for (auto& o : obs) o.weight = o.previous_weight;  // weights and system stay consistent
        break;
      }
      sys.a = next.a;
      sys.r = next.r;
      sys.weight_sum = next.weight_sum;
      if (change < 1e-3) break;
    }
    sys.Decompose();
  }

  // Per-channel albedo for a fixed normal: rho_c = pi * sum w rgb_c m / sum w m^2, m = max(0, s.n).
  // cos_floor > 0 bounds the cosine from below (m >= cos_floor |s|): for a normal that came from the
  // neighbours rather than the data, a light nearly perpendicular to it would otherwise turn its
  // observation into an unbounded albedo.
  static Vector3d AlbedoFor(const std::vector<PixelObservation>& obs, const Vector3d& n, double cos_floor = 0.0) {
    Vector3d num = Vector3d::Zero();
    double den = 0.0;
    for (const auto& o : obs) {
      if (o.weight <= 0.0) continue;
      const double m = std::max(cos_floor * o.s.norm(), o.s.dot(n));
      num += o.weight * m * o.rgb;
      den += o.weight * m * m;
    }
    if (!(den > 0.0)) return Vector3d::Zero();
    return (std::numbers::pi * num / den).cwiseMax(0.0);
  }

  // Relative RMS residual (shading units over |b|) of the weighted fit with normal n, albedo rho.
  static double RelativeResidual(const std::vector<PixelObservation>& obs, const Vector3d& n, const Vector3d& rho) {
    const double bg = rho.mean() / std::numbers::pi;
    if (!(bg > 0.0)) return 0.0;
    double s2 = 0.0, ws = 0.0;
    for (const auto& o : obs) {
      if (o.weight <= 0.0) continue;
      const double u = (o.grey - bg * std::max(0.0, o.s.dot(n))) * o.inv_e;
      s2 += o.weight * u * u;
      ws += o.weight;
    }
    return ws > 0.0 ? std::sqrt(s2 / ws) / bg : 0.0;
  }

  // Clamps n_z to min_normal_z keeping the azimuth; returns the confidence factor (1 = untouched).
  double ClampNormal(Vector3d& n, std::uint8_t& state) const {
    const double m = options_.min_normal_z;
    if (n.z() >= m) return 1.0;
    const double raw_z = n.z();
    const double t = std::hypot(n.x(), n.y());
    if (t > 0.0) {
      n.x() *= std::sqrt(1.0 - m * m) / t;
      n.y() *= std::sqrt(1.0 - m * m) / t;
      n.z() = m;
    } else {
      n = Vector3d::UnitZ();
    }
    state |= kClamped;
    return std::clamp(raw_z / m, 0.0, 1.0);
  }

  double ConditionFactor(double condition) const {
    if (condition <= options_.good_condition) return 1.0;
    if (condition >= options_.max_condition) return 0.0;
    return 1.0 - std::log(condition / options_.good_condition) / std::log(options_.max_condition / options_.good_condition);
  }

  // The pixel's final normal, albedo and confidence from its weighted system. prior: the
  // neighbours' normal, used when the pixel needs regularisation (null in the first pass).
  void Finish(Scratch& scratch, const PixelSystem& sys, const Vector3d* prior, PixelEstimate& est, Vector3d& albedo,
              bool low_confidence = false) const {
    const auto& obs = scratch.obs;
    est.condition = sys.Condition(options_.max_reported_condition);
    est.used = 0;
    for (const auto& o : obs) est.used += o.weight > 0.5;
    const bool ill = est.used < 3 || est.condition >= options_.max_condition;
    if (ill) est.state |= kIllConditioned;

    Vector3d n = Vector3d::Zero();
    Matrix3d b = sys.Solve();
    Vector3d bg = b.rowwise().mean();
    const double albedo_grey = std::numbers::pi * bg.norm();
    const bool low_albedo = albedo_grey < options_.reliable_albedo;
    if (low_albedo) est.state |= kLowAlbedo;
    if (prior != nullptr && (ill || low_albedo || low_confidence)) {
      // Tikhonov toward rho_prior * n_prior: the data fixes what it constrains, the neighbours the rest.
      const Vector3d rho_prior = AlbedoFor(obs, *prior, kRegularisedCosFloor) / std::numbers::pi;
      const double strength = ill || low_confidence ? 1.0 : 1.0 - albedo_grey / options_.reliable_albedo;
      const double lambda = options_.regularisation * strength * std::max(sys.eigenvalues(2), 1e-300);
      b = sys.Solve(lambda, *prior * rho_prior.transpose());
      bg = b.rowwise().mean();
      est.state |= kRegularised;
    }
    const double len = bg.norm();
    if (len > 0.0 && std::isfinite(len)) {
      n = bg / len;
    } else {
      n = prior != nullptr ? *prior : Vector3d::UnitZ();
    }
    const double nz_factor = ClampNormal(n, est.state);
    albedo = AlbedoFor(obs, n, (est.state & kRegularised) ? kRegularisedCosFloor : 0.0);

    const double count_factor = est.used < 3 ? 0.0 : (est.used == 3 ? 0.5 : 1.0);
    const double rel = RelativeResidual(obs, n, albedo) / options_.residual_tolerance;
    const double fit_factor = 1.0 / (1.0 + rel * rel);
    const double albedo_factor = std::min(1.0, albedo.mean() / options_.reliable_albedo);
    est.confidence = std::clamp(count_factor * ConditionFactor(est.condition) * fit_factor * albedo_factor * nz_factor, 0.0, 1.0);
    if (!std::isfinite(est.confidence)) est.confidence = 0.0;
    est.normal = n;
  }

 private:
  const Stack& stack_;
  const PhotometricStereoOptions& options_;
  std::vector<int> selected_;
  bool has_point_lights_ = false;
  double roughness_ = -1.0;
};


// Steepest normal (n_z, i.e. cos of the view angle for a camera above) re-weighted for the Burley lobe.
constexpr double kBurleyMinNormalZ = 0.3;

// Weigh + Finish, then (kBurley) the re-weighting rounds: each divides the observations by the
// diffuse lobe's factor at the last normal and solves again. `est.state` on entry is kept as the
// base of every round's flags.
void SolvePixel(const Solver& solver, const PhotometricStereoOptions& options, Scratch& scratch, PixelSystem& sys,
                const Vector3d* prior, PixelEstimate& est, Vector3d& albedo, bool low_confidence = false) {
  const std::uint8_t base_state = est.state;
  solver.Weigh(scratch, sys);
  solver.Finish(scratch, sys, prior, est, albedo, low_confidence);
  if (!solver.burley()) return;
  // The lobe's view factor changes fast near grazing view, where the re-weighting need not
  // converge; such pixels (and those the data cannot place) keep Lambert's solve.
  if ((est.state & (kClamped | kIllConditioned)) != 0 || est.normal.z() < kBurleyMinNormalZ) return;
  for (int it = 0; it < options.diffuse_iterations; ++it) {
    solver.ApplyDiffuseModel(scratch, est.normal);
    est.state = base_state;
    solver.Weigh(scratch, sys);
    solver.Finish(scratch, sys, prior, est, albedo, low_confidence);
  }
}

// kBurley: mean squared residual, in the observations' own units (raw, not re-weighted) relative
// to the albedo, of the pixel's weighted fit: what the roughness estimate minimises.
double RawRelativeResidual2(const std::vector<PixelObservation>& obs, const Vector3d& n, const Vector3d& rho) {
  const double bg = rho.mean() / std::numbers::pi;
  if (!(bg > 0.0)) return -1.0;
  double s2 = 0.0, ws = 0.0;
  for (const auto& o : obs) {
    if (o.weight <= 0.0) continue;
    const double cos_l = o.s.dot(n);
    const double factor = (1.0 + o.fd90_minus_1 * SchlickWeight(std::max(0.0, n.dot(o.l)))) *
                          (1.0 + o.fd90_minus_1 * SchlickWeight(std::max(0.0, n.dot(o.v))));
    const double u = (o.raw_rgb.mean() - factor * bg * std::max(0.0, cos_l)) * o.inv_e;
    s2 += o.weight * u * u;
    ws += o.weight;
  }
  return ws > 0.0 ? s2 / ws / (bg * bg) : -1.0;
}

// Prior normal for the pixels that need one, from their reliable neighbours: the weighted mean
// over the 3x3 neighbourhood, else push-pull over a pyramid (2x2 sums down, blend back up), +z when
// nothing anywhere is reliable. Pyramid levels start at half size, in float: about 1.4 floats per
// pixel beyond the output.
Image NeighbourPrior(const Image& normal, const std::vector<float>& weight, const std::vector<std::uint8_t>& needs,
                     int w, int h) {
  const std::size_t n = static_cast<std::size_t>(w) * h;
  struct Level {
    int w = 0, h = 0;
    std::vector<Eigen::Vector4f> sum;  // weighted normal (xyz) and weight (w)
  };
  std::vector<Level> levels;
  auto level0 = [&](int r, int c) {
    const std::size_t i = static_cast<std::size_t>(r) * w + c;
    const float wt = weight[i];
    return Eigen::Vector4f(wt * normal.data()[i], wt * normal.data()[n + i], wt * normal.data()[2 * n + i], wt);
  };
  int lw = w, lh = h;
  while (lw > 1 || lh > 1) {
    Level g;
    g.w = (lw + 1) / 2, g.h = (lh + 1) / 2;
    g.sum.assign(static_cast<std::size_t>(g.w) * g.h, Eigen::Vector4f::Zero());
    for (int r = 0; r < lh; ++r)
      for (int c = 0; c < lw; ++c) {
        const Eigen::Vector4f v = levels.empty() ? level0(r, c) : levels.back().sum[static_cast<std::size_t>(r) * lw + c];
        g.sum[static_cast<std::size_t>(r / 2) * g.w + c / 2] += v;
      }
    lw = g.w, lh = g.h;
    levels.push_back(std::move(g));
  }
  // Pull, coarse to fine, down to level 1 (half size): filled value per pyramid pixel.
  auto mean_of = [](const Eigen::Vector4f& v, const Eigen::Vector3f& fallback) {
    const float a = std::min(1.0f, v(3));
    return v(3) > 0.0f ? Eigen::Vector3f(a * v.head<3>() / v(3) + (1.0f - a) * fallback) : fallback;
  };
  std::vector<Eigen::Vector3f> coarse(1, Eigen::Vector3f::UnitZ());
  int cw = 1;
  for (int li = static_cast<int>(levels.size()) - 1; li >= 0; --li) {
    const Level& f = levels[li];
    std::vector<Eigen::Vector3f> filled(f.sum.size());
    for (int r = 0; r < f.h; ++r)
      for (int c = 0; c < f.w; ++c) {
        const std::size_t i = static_cast<std::size_t>(r) * f.w + c;
        const Eigen::Vector3f& up = li + 1 == static_cast<int>(levels.size()) ? coarse[0] : coarse[static_cast<std::size_t>(r / 2) * cw + c / 2];
        filled[i] = mean_of(f.sum[i], up);
      }
    coarse.swap(filled);
    cw = f.w;
  }
  Image prior(w, h, 3, 0.0f, normal.pitch_mm());
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * w + c;
      Eigen::Vector3f p = Eigen::Vector3f::UnitZ();
      if (needs[i]) {
        Eigen::Vector4f sum = Eigen::Vector4f::Zero();
        for (int dr = -1; dr <= 1; ++dr)
          for (int dc = -1; dc <= 1; ++dc) {
            const int rr = r + dr, cc = c + dc;
            if ((dr == 0 && dc == 0) || rr < 0 || rr >= h || cc < 0 || cc >= w) continue;
            sum += level0(rr, cc);
          }
        const Eigen::Vector3f up = levels.empty() ? Eigen::Vector3f::UnitZ() : coarse[static_cast<std::size_t>(r / 2) * cw + c / 2];
        p = sum(3) >= 0.5f ? Eigen::Vector3f(sum.head<3>() / sum(3)) : up;
        if (!(p.norm() > 1e-6f) || !p.allFinite()) p = Eigen::Vector3f::UnitZ();
        p.normalize();
        if (p.z() < 0.05f) p = Eigen::Vector3f::UnitZ();
      }
      for (int k = 0; k < 3; ++k) prior.data()[k * n + i] = p(k);
    }
  return prior;
}

void CheckStack(const Stack& stack, const PhotometricStereoOptions& options) {
  const MetricGrid& g = stack.grid;
  if (g.width <= 0 || g.height <= 0) throw std::invalid_argument("photometric stereo: empty grid");
  if (!(g.pitch_mm > 0.0)) throw std::invalid_argument("photometric stereo: grid pitch_mm must be > 0");
  if (options.view >= 0 && !stack.views.empty() && options.view >= static_cast<int>(stack.views.size()))
    throw std::invalid_argument("photometric stereo: option view out of range");
  const std::size_t n = static_cast<std::size_t>(g.width) * g.height;
  for (std::size_t k = 0; k < stack.observations.size(); ++k) {
    const Observation& o = stack.observations[k];
    const std::string where = "photometric stereo: observation " + std::to_string(k) + ": ";
    if (o.light < 0 || o.light >= static_cast<int>(stack.lights.size())) throw std::invalid_argument(where + "light index out of range");
    if (!stack.views.empty() && (o.view < 0 || o.view >= static_cast<int>(stack.views.size())))
      throw std::invalid_argument(where + "view index out of range");
    if (o.rgb.width() != g.width || o.rgb.height() != g.height || (o.rgb.channels() != 3 && o.rgb.channels() != 1))
      throw std::invalid_argument(where + "rgb must be 1 or 3 channels on the grid");
    if (!o.irradiance.empty() && (o.irradiance.width() != g.width || o.irradiance.height() != g.height || o.irradiance.channels() != 1))
      throw std::invalid_argument(where + "irradiance must be 1 channel on the grid");
    if (!o.flags.empty() && o.flags.size() != n) throw std::invalid_argument(where + "flags must have width*height entries");
  }
}

// The checks of SolvePhotometricStereoAt and SolvePhotometricStereoAgain: options, stack, height.
void CheckSolveAt(const Stack& stack, const PhotometricStereoOptions& options, const Image& height_mm) {
  if (!options.Check()) throw std::invalid_argument("photometric stereo: options fail Check()");
  CheckStack(stack, options);
  if (height_mm.width() != stack.grid.width || height_mm.height() != stack.grid.height || height_mm.channels() != 1) {
    throw std::invalid_argument("photometric stereo: height_mm must be 1 channel on the grid");
  }
}

// What SolveAt may keep of an earlier solve of the same stack (SolvePhotometricStereoAgain).
struct EarlierSolve {
  const PhotometricStereoResult* result = nullptr;  // null: solve every pixel
  std::uint8_t changed_flag = 0;                    // observations flagged so since then
};

// One full solve with every pixel at the given height (mm); with `earlier`, a pixel whose
// observations carry no `changed_flag` and that the earlier solve did not solve in its second
// pass (with the neighbours) keeps the earlier estimate.
PhotometricStereoResult SolveAt(const Solver& solver, const Stack& stack, const PhotometricStereoOptions& options,
                                const Image& height_mm, const EarlierSolve& earlier = {}) {
  const int w = stack.grid.width, h = stack.grid.height;
  const std::size_t n = static_cast<std::size_t>(w) * h;
  const double pitch = stack.grid.pitch_mm;
  PhotometricStereoResult res;
  res.normal = Image(w, h, 3, 0.0f, pitch);
  res.albedo = Image(w, h, 3, 0.0f, pitch);
  res.confidence = Image(w, h, 1, 0.0f, pitch);
  res.condition_number = Image(w, h, 1, 0.0f, pitch);
  res.used_lights = Image(w, h, 1, 0.0f, pitch);
  std::vector<std::uint8_t> state(n, 0);
  auto height_at = [&](std::size_t i) { return static_cast<double>(height_mm.data()[i]); };
  // The earlier estimate of pixel i, when it stands (see above).
  const PhotometricStereoResult* before = earlier.result;
  auto keeps_earlier = [&](std::size_t i) {
    if (before == nullptr || (before->pixel_states[i] & kSecondPass) != 0) return false;
    for (const Observation& o : stack.observations) {
      if (!o.flags.empty() && (o.flags[i] & earlier.changed_flag) != 0) return false;
    }
    return true;
  };
  auto keep_earlier = [&](std::size_t i) {
    for (int c = 0; c < 3; ++c) {
      res.normal.data()[c * n + i] = before->normal.data()[c * n + i];
      res.albedo.data()[c * n + i] = before->albedo.data()[c * n + i];
    }
    res.confidence.data()[i] = before->confidence.data()[i];
    res.condition_number.data()[i] = before->condition_number.data()[i];
    res.used_lights.data()[i] = before->used_lights.data()[i];
    state[i] = before->pixel_states[i];
  };
  auto store = [&](std::size_t i, const PixelEstimate& est, const Vector3d& albedo) {
    for (int c = 0; c < 3; ++c) {
      res.normal.data()[c * n + i] = static_cast<float>(est.normal(c));
      // Garbage input (e.g. a near-zero irradiance) must not overflow the float map.
      const double a = std::isfinite(albedo(c)) ? std::clamp(albedo(c), 0.0, kMaxAlbedo) : 0.0;
      res.albedo.data()[c * n + i] = static_cast<float>(a);
    }
    res.confidence.data()[i] = static_cast<float>(est.confidence);
    res.condition_number.data()[i] = static_cast<float>(est.condition);
    res.used_lights.data()[i] = static_cast<float>(est.used);
    state[i] = est.state;
  };

  // Pass 1: every pixel on its own.
  std::atomic<std::size_t> kept{0};
  ParallelFor(h, [&](std::size_t r0, std::size_t r1) {
    Scratch scratch(solver.observation_count());
    PixelSystem sys;
    std::size_t chunk_kept = 0;
    for (std::size_t r = r0; r < r1; ++r)
      for (int c = 0; c < w; ++c) {
        const std::size_t i = r * w + c;
        if (keeps_earlier(i)) {
          keep_earlier(i);
          ++chunk_kept;
          continue;
        }
        PixelEstimate est;
        Vector3d albedo = Vector3d::Zero();
        if (solver.Gather(static_cast<int>(r), c, height_at(i), scratch) == 0) {
          est.state = kDark | kIllConditioned;
          est.condition = options.max_reported_condition;
        } else {
          SolvePixel(solver, options, scratch, sys, nullptr, est, albedo);
          if (est.confidence < options.regularise_below_confidence) est.state |= kLowConfidence;
        }
        store(i, est, albedo);
      }
    kept += chunk_kept;
  });
  res.kept_pixels = static_cast<long long>(kept.load());

  // Pass 2: pixels that need their neighbours (dark, ill-conditioned, albedo near zero).
  std::vector<float> reliable(n);
  bool any_unreliable = false;
  for (std::size_t i = 0; i < n; ++i) {
    const bool needs = (state[i] & kNeedsNeighbours) != 0;
    reliable[i] = needs ? 0.0f : res.confidence.data()[i];
    any_unreliable |= needs;
  }
  if (any_unreliable) {
    std::vector<std::uint8_t> needs(n);
    for (std::size_t i = 0; i < n; ++i) needs[i] = (state[i] & kNeedsNeighbours) != 0;
    const Image prior = NeighbourPrior(res.normal, reliable, needs, w, h);
    ParallelFor(h, [&](std::size_t r0, std::size_t r1) {
      Scratch scratch(solver.observation_count());
      PixelSystem sys;
      for (std::size_t r = r0; r < r1; ++r)
        for (int c = 0; c < w; ++c) {
          const std::size_t i = r * w + c;
          if ((state[i] & kNeedsNeighbours) == 0) continue;
          const Vector3d p(prior.data()[i], prior.data()[n + i], prior.data()[2 * n + i]);
          PixelEstimate est;
          Vector3d albedo = Vector3d::Zero();
          if (state[i] & kDark) {
            est.normal = p;
            est.state = kDark | kIllConditioned | kRegularised;
            est.condition = options.max_reported_condition;
          } else {
            solver.Gather(static_cast<int>(r), c, height_at(i), scratch);
            SolvePixel(solver, options, scratch, sys, &p, est, albedo, (state[i] & kLowConfidence) != 0);
          }
          est.state |= kSecondPass;
          store(i, est, albedo);
        }
    });
  }
  for (std::size_t i = 0; i < n; ++i) {
    res.dark_pixels += (state[i] & kDark) != 0;
    res.ill_conditioned_pixels += (state[i] & kIllConditioned) != 0;
    res.low_albedo_pixels += (state[i] & (kLowAlbedo | kDark)) != 0;
    res.clamped_normal_pixels += (state[i] & kClamped) != 0;
    res.regularised_pixels += (state[i] & kRegularised) != 0;
  }
  res.pixel_states = std::move(state);
  return res;
}

// kBurley: the diffuse roughness that leaves the least residual, over a sample of at most
// ~kRoughnessSamplePixels pixels at height `height_mm`: a grid over [0, 1], then a parabola
// through the best grid point and its neighbours; -1 (Lambert's law) when that fits better still
// (a matte surface that is not Principled). Sums run in pixel order (thread-count independent).
constexpr int kRoughnessSamplePixels = 4096;
constexpr int kRoughnessGridSteps = 5;  // r = 0, 0.2, ..., 1

double EstimateDiffuseRoughness(Solver& solver, const Stack& stack, const PhotometricStereoOptions& options,
                                double height_mm) {
  const int w = stack.grid.width, h = stack.grid.height;
  const int stride = std::max(1, static_cast<int>(std::sqrt(static_cast<double>(w) * h / kRoughnessSamplePixels)));
  const int rows = (h + stride - 1) / stride, cols = (w + stride - 1) / stride;
  // Lambert's solve picks the pixels every candidate is judged on (well placed, not too steep) and
  // is the last candidate; a pixel a candidate cannot solve counts with Lambert's residual.
  std::vector<double> lambert(static_cast<std::size_t>(rows) * cols, -1.0), per_pixel(lambert.size());
  auto residuals = [&](std::vector<double>& out, bool first) {
    ParallelFor(rows, [&](std::size_t r0, std::size_t r1) {
      Scratch scratch(solver.observation_count());
      PixelSystem sys;
      for (std::size_t rr = r0; rr < r1; ++rr)
        for (int cc = 0; cc < cols; ++cc) {
          const std::size_t i = rr * cols + cc;
          out[i] = -1.0;
          if (!first && lambert[i] < 0.0) continue;
          const int r = static_cast<int>(rr) * stride, c = cc * stride;
          if (solver.Gather(r, c, height_mm, scratch) < 4) continue;
          PixelEstimate est;
          Vector3d albedo;
          SolvePixel(solver, options, scratch, sys, nullptr, est, albedo);
          if (first && (est.confidence < options.regularise_below_confidence || (est.state & kClamped) != 0 ||
                        est.normal.z() < kBurleyMinNormalZ)) {
            continue;
          }
          out[i] = RawRelativeResidual2(scratch.obs, est.normal, albedo);
        }
    });
  };
  solver.set_roughness(-1.0);
  residuals(lambert, true);
  std::vector<double> cost(kRoughnessGridSteps + 2, 0.0);  // [0, steps]: Burley r = g / steps; last: Lambert
  for (double v : lambert) cost.back() += std::max(0.0, v);
  for (int g = 0; g <= kRoughnessGridSteps; ++g) {
    solver.set_roughness(static_cast<double>(g) / kRoughnessGridSteps);
    residuals(per_pixel, false);
    for (std::size_t i = 0; i < per_pixel.size(); ++i) {
      if (lambert[i] >= 0.0) cost[g] += per_pixel[i] >= 0.0 ? per_pixel[i] : lambert[i];
    }
  }
  const int best = static_cast<int>(std::min_element(cost.begin(), cost.end() - 1) - cost.begin());
  if (cost.back() <= cost[best]) return -1.0;
  const double step = 1.0 / kRoughnessGridSteps;
  double r = best * step;
  if (best > 0 && best < kRoughnessGridSteps) {
    const double cm = cost[best - 1], c0 = cost[best], cp = cost[best + 1];
    const double curvature = cm - 2.0 * c0 + cp;
    if (curvature > 0.0) r -= 0.5 * step * (cp - cm) / curvature;
  }
  return std::clamp(r, 0.0, 1.0);
}

// kBurley: sets the solver's diffuse roughness, the given one or the least-residual estimate at the
// anchor plane (one rule for RunPhotometricStereo, SolvePhotometricStereoAt and
// ChooseDiffuseRoughness). Leaves the solver on Lambert's law for kLambert.
void SetDiffuseRoughness(Solver& solver, const Stack& stack, const PhotometricStereoOptions& options) {
  if (options.diffuse_model != DiffuseModel::kBurley) return;
  solver.set_roughness(options.diffuse_roughness >= 0.0
                           ? options.diffuse_roughness
                           : EstimateDiffuseRoughness(solver, stack, options, options.integration.mean_height_mm));
}

}  // namespace

PhotometricStereoResult RunPhotometricStereo(const Stack& stack, const PhotometricStereoOptions& options,
                                             const ProgressCallback& progress) {
  if (!options.Check()) throw std::invalid_argument("photometric stereo: options fail Check()");
  CheckStack(stack, options);
  Solver solver(stack, options);
  const int w = stack.grid.width, h = stack.grid.height;
  ReportProgress(progress, "photometric stereo", 0.0);
  if (options.diffuse_model == DiffuseModel::kBurley) {
    SetDiffuseRoughness(solver, stack, options);
    if (solver.burley()) {
      LogInfo() << "photometric stereo: Burley diffuse lobe, roughness " << solver.roughness()
                << (options.diffuse_roughness >= 0.0 ? " (given)" : " (least residual)");
    } else {
      LogInfo() << "photometric stereo: Lambert's law fits better than any Burley diffuse lobe";
    }
  }
  // Start on the anchor plane: every pixel at the mean height.
  const Image start(w, h, 1, static_cast<float>(options.integration.mean_height_mm), stack.grid.pitch_mm);
  PhotometricStereoResult result = SolveAt(solver, stack, options, start);
  if (solver.has_point_lights() && options.refine_height) {
    result = RefineNearLightHeights(
        std::move(result), options, stack.grid.pitch_mm,
        [&](const Image& height) { return SolveAt(solver, stack, options, height); }, [](const Image&, bool) {}, progress);
  }
  if (solver.has_point_lights() && result.height_mm.empty()) result.height_mm = start;
  result.diffuse_roughness = solver.burley() ? solver.roughness() : -1.0;
  ReportProgress(progress, "photometric stereo", 1.0);
  return result;
}

PhotometricStereoResult SolvePhotometricStereoAt(const Stack& stack, const PhotometricStereoOptions& options,
                                                 const Image& height_mm) {
  CheckSolveAt(stack, options, height_mm);
  Solver solver(stack, options);
  SetDiffuseRoughness(solver, stack, options);
  PhotometricStereoResult result = SolveAt(solver, stack, options, height_mm);
  result.diffuse_roughness = solver.burley() ? solver.roughness() : -1.0;
  return result;
}

PhotometricStereoResult SolvePhotometricStereoAgain(const Stack& stack, const PhotometricStereoOptions& options,
                                                    const Image& height_mm, const PhotometricStereoResult& previous,
                                                    std::uint8_t changed_flag) {
  CheckSolveAt(stack, options, height_mm);
  const std::size_t n = static_cast<std::size_t>(stack.grid.width) * stack.grid.height;
  auto on_grid = [&](const Image& image, int channels) {
    return image.width() == stack.grid.width && image.height() == stack.grid.height && image.channels() == channels;
  };
  if (previous.pixel_states.size() != n || !on_grid(previous.normal, 3) || !on_grid(previous.albedo, 3) ||
      !on_grid(previous.confidence, 1) || !on_grid(previous.condition_number, 1) || !on_grid(previous.used_lights, 1)) {
    throw std::invalid_argument("photometric stereo: the previous solve is not of this grid");
  }
  Solver solver(stack, options);
  if (solver.has_point_lights()) {
    throw std::invalid_argument("photometric stereo: a partial solve again needs distant lights (point lights move with the height)");
  }
  SetDiffuseRoughness(solver, stack, options);
  PhotometricStereoResult result = SolveAt(solver, stack, options, height_mm, EarlierSolve{&previous, changed_flag});
  result.diffuse_roughness = solver.burley() ? solver.roughness() : -1.0;
  const auto kept = static_cast<std::size_t>(result.kept_pixels);
  LogInfo() << "photometric stereo: solved again " << (100.0 * static_cast<double>(n - kept) / static_cast<double>(n))
            << " % of the pixels (the others carry no new mark)";
  return result;
}

double ChooseDiffuseRoughness(const Stack& stack, const PhotometricStereoOptions& options) {
  if (!options.Check()) throw std::invalid_argument("photometric stereo: options fail Check()");
  CheckStack(stack, options);
  Solver solver(stack, options);
  SetDiffuseRoughness(solver, stack, options);
  return solver.burley() ? solver.roughness() : -1.0;
}

PhotometricStereoResult RefineNearLightHeights(PhotometricStereoResult result, const PhotometricStereoOptions& options,
                                               double pitch_mm,
                                               const std::function<PhotometricStereoResult(const Image&)>& solve_at,
                                               const AtRefinementHeight& at_height, const ProgressCallback& progress) {
  IntegrationOptions integration = options.integration;
  integration.pitch_mm = pitch_mm;
  double previous_change = std::numeric_limits<double>::infinity();
  for (int it = 1; it <= options.max_near_iterations; ++it) {
    ReportProgress(progress, "photometric stereo", static_cast<double>(it) / (options.max_near_iterations + 1));
    // Confidence as integration weights: unreliable normals do not bend the height.
    Image height = IntegrateNormals(result.normal, result.confidence, integration).height_mm;
    at_height(height, false);
    PhotometricStereoResult next = solve_at(height);
    const double change = MeanNormalAngleDeg(next.normal, result.normal);
    if (change >= previous_change) {
      // Not converging (normals too unreliable to place the surface): keep the last round,
      // whose change was the smallest.
      LogWarning() << "photometric stereo: near-light refinement diverges (mean normal change " << change
                   << " deg after " << previous_change << " deg); kept round " << it - 1;
      at_height(result.height_mm, true);
      break;
    }
    previous_change = change;
    result = std::move(next);
    result.height_mm = std::move(height);
    result.near_iterations = it;
    result.last_normal_change_deg = change;
    if (change < options.near_tolerance_deg) break;
  }
  if (result.near_iterations == options.max_near_iterations && result.last_normal_change_deg >= options.near_tolerance_deg)
    LogWarning() << "photometric stereo: near-light refinement stopped after " << result.near_iterations
                 << " rounds, normals still changing by " << result.last_normal_change_deg << " deg";
  return result;
}

double MeanNormalAngleDeg(const Image& a, const Image& b) {
  const std::size_t n = a.pixel_count();
  double sum = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    // atan2(|a x b|, a . b): exact for tiny angles, where acos of a float dot product is not.
    const Vector3d va(a.data()[i], a.data()[n + i], a.data()[2 * n + i]);
    const Vector3d vb(b.data()[i], b.data()[n + i], b.data()[2 * n + i]);
    sum += std::atan2(va.cross(vb).norm(), va.dot(vb));
  }
  return n > 0 ? sum / n * 180.0 / std::numbers::pi : 0.0;
}

}  // namespace u3mscan::reconstruction
