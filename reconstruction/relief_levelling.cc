#include "reconstruction/relief_levelling.h"

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <vector>

#include "core/parallel.h"

namespace u3mscan::reconstruction {
namespace {

// The smallest eigenvalue of the normal matrix against its largest below which the pixels'
// layout does not fix every term of the surface.
constexpr double kMinEigenvalueRatio = 1e-9;

using Vector6d = Eigen::Matrix<double, 6, 1>;
using Matrix6d = Eigen::Matrix<double, 6, 6>;

int TermCount(Levelling levelling) {
  switch (levelling) {
    case Levelling::kNone: return 0;
    case Levelling::kPlane: return 3;
    case Levelling::kQuadratic: return 6;
  }
  return 0;
}

// The map's centre-relative coordinates of a pixel centre: -1..1 across the width and height.
struct MapCoordinates {
  double half_width, half_height;
  double U(int col) const { return (col + 0.5 - half_width) / half_width; }
  double V(int row) const { return (row + 0.5 - half_height) / half_height; }
};

Vector6d Basis(double u, double v) {
  Vector6d b;
  b << 1.0, u, v, u * u, u * v, v * v;
  return b;
}

// The removed surface (constant left out) and its slopes in world units (mm per mm): x grows with
// the columns, y against the rows.
struct SurfacePoint {
  double z_mm, dz_dx, dz_dy;
};
SurfacePoint Evaluate(const std::array<double, 6>& c, const MapCoordinates& m, double pitch_mm, int col, int row) {
  const double u = m.U(col), v = m.V(row);
  const double dz_du = c[1] + 2.0 * c[3] * u + c[4] * v;
  const double dz_dv = c[2] + c[4] * u + 2.0 * c[5] * v;
  return {c[1] * u + c[2] * v + c[3] * u * u + c[4] * u * v + c[5] * v * v, dz_du / (m.half_width * pitch_mm),
          -dz_dv / (m.half_height * pitch_mm)};
}

}  // namespace

std::string LevellingName(Levelling levelling) {
  switch (levelling) {
    case Levelling::kNone: return "none";
    case Levelling::kPlane: return "plane";
    case Levelling::kQuadratic: return "quadratic";
  }
  return "none";
}

Levelling ParseLevelling(const std::string& name) {
  if (name == "none") return Levelling::kNone;
  if (name == "plane") return Levelling::kPlane;
  if (name == "quadratic") return Levelling::kQuadratic;
  throw std::invalid_argument("levelling must be none, plane or quadratic, got '" + name + "'");
}

LevellingResult LevelRelief(Levelling levelling, Image* height_mm, Image* normal, const Image& weight) {
  if (height_mm == nullptr) throw std::invalid_argument("LevelRelief: no height map");
  LevellingResult result;
  const int terms = TermCount(levelling);
  if (terms == 0 || height_mm->empty()) return result;
  const int w = height_mm->width(), h = height_mm->height();
  if (height_mm->channels() < 1) throw std::invalid_argument("LevelRelief: the height map has no channel");
  if (normal != nullptr && !normal->empty() && (normal->width() != w || normal->height() != h || normal->channels() < 3)) {
    throw std::invalid_argument("LevelRelief: the normal map must have 3 channels and the height map's size");
  }
  if (!weight.empty() && (weight.width() != w || weight.height() != h)) {
    throw std::invalid_argument("LevelRelief: the weight map must have the height map's size");
  }
  const double pitch_mm = height_mm->pitch_mm() > 0.0 ? height_mm->pitch_mm() : 1.0;
  const MapCoordinates m{0.5 * w, 0.5 * h};
  auto pixel_weight = [&](int row, int col) -> double {
    const float z = height_mm->at(0, row, col);
    if (!std::isfinite(z)) return 0.0;
    if (weight.empty()) return 1.0;
    const float a = weight.at(0, row, col);
    return std::isfinite(a) && a > 0.0f ? a : 0.0;
  };

  // Normal equations, one row at a time (rows summed in order: the same result on any thread count).
  std::vector<Matrix6d> row_ata(static_cast<std::size_t>(h), Matrix6d::Zero());
  std::vector<Vector6d> row_atz(static_cast<std::size_t>(h), Vector6d::Zero());
  std::vector<double> row_weight(static_cast<std::size_t>(h), 0.0);
  ParallelFor(static_cast<std::size_t>(h), [&](std::size_t begin, std::size_t end) {
    for (std::size_t r = begin; r < end; ++r) {
      const int row = static_cast<int>(r);
      Matrix6d ata = Matrix6d::Zero();
      Vector6d atz = Vector6d::Zero();
      double sum = 0.0;
      for (int col = 0; col < w; ++col) {
        const double a = pixel_weight(row, col);
        if (a <= 0.0) continue;
        const Vector6d b = Basis(m.U(col), m.V(row));
        ata.selfadjointView<Eigen::Lower>().rankUpdate(b, a);
        atz += a * static_cast<double>(height_mm->at(0, row, col)) * b;
        sum += a;
      }
      row_ata[r] = ata.selfadjointView<Eigen::Lower>();
      row_atz[r] = atz;
      row_weight[r] = sum;
    }
  });
  Matrix6d ata = Matrix6d::Zero();
  Vector6d atz = Vector6d::Zero();
  double total = 0.0;
  for (int r = 0; r < h; ++r) {
    ata += row_ata[static_cast<std::size_t>(r)];
    atz += row_atz[static_cast<std::size_t>(r)];
    total += row_weight[static_cast<std::size_t>(r)];
  }
  const Eigen::MatrixXd a = ata.topLeftCorner(terms, terms);
  const Eigen::VectorXd b = atz.head(terms);
  // Too few weighted pixels for the order (a line of pixels cannot fix a bowl across it): change
  // nothing. The basis lies in -1..1, so the normal matrix is well scaled and its eigenvalues'
  // ratio tells a degenerate layout (a full map: 0.05 for the quadratic) from round-off.
  if (total <= 0.0) return result;
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(a, Eigen::EigenvaluesOnly);
  const Eigen::VectorXd lambda = eigen.eigenvalues();
  if (eigen.info() != Eigen::Success || !(lambda.minCoeff() > kMinEigenvalueRatio * lambda.maxCoeff())) return result;
  const Eigen::VectorXd c = a.ldlt().solve(b);
  if (!c.allFinite()) return result;
  for (int i = 0; i < terms; ++i) result.coefficients_mm[static_cast<std::size_t>(i)] = c(i);
  result.weighted_pixels = total;

  // Subtract the surface less its weighted mean, so that the levelled map keeps the mean height it
  // had. Row 0 of the normal matrix holds the weighted sums of the basis terms.
  const double surface_mean = ata.row(0).head(terms).dot(c) / total;
  const double constant = c(0) - surface_mean;  // added to Evaluate's z, which leaves c(0) out
  std::vector<double> row_lo(static_cast<std::size_t>(h), std::numeric_limits<double>::infinity());
  std::vector<double> row_hi(static_cast<std::size_t>(h), -std::numeric_limits<double>::infinity());
  std::vector<double> row_tilt(static_cast<std::size_t>(h), 0.0);
  const bool rotate = normal != nullptr && !normal->empty();
  // The rotation that lays the removed tilt's normal on +z (the bowl is left in the normals: header).
  std::array<double, 6> tilt_only{};
  tilt_only[1] = result.coefficients_mm[1];
  tilt_only[2] = result.coefficients_mm[2];
  const SurfacePoint tilt_slope = Evaluate(tilt_only, m, pitch_mm, 0, 0);
  const Eigen::Quaterniond level = Eigen::Quaterniond::FromTwoVectors(
      Eigen::Vector3d(-tilt_slope.dz_dx, -tilt_slope.dz_dy, 1.0).normalized(), Eigen::Vector3d::UnitZ());
  ParallelFor(static_cast<std::size_t>(h), [&](std::size_t begin, std::size_t end) {
    for (std::size_t r = begin; r < end; ++r) {
      const int row = static_cast<int>(r);
      for (int col = 0; col < w; ++col) {
        const SurfacePoint s = Evaluate(result.coefficients_mm, m, pitch_mm, col, row);
        float& z = height_mm->at(0, row, col);
        if (std::isfinite(z)) z = static_cast<float>(z - (s.z_mm + constant));
        if (pixel_weight(row, col) > 0.0) {
          row_lo[r] = std::min(row_lo[r], s.z_mm);
          row_hi[r] = std::max(row_hi[r], s.z_mm);
        }
        row_tilt[r] = std::max(row_tilt[r], std::hypot(s.dz_dx, s.dz_dy));
        if (!rotate) continue;
        const Eigen::Vector3d n(normal->at(0, row, col), normal->at(1, row, col), normal->at(2, row, col));
        if (!n.allFinite()) continue;
        const Eigen::Vector3d levelled = level * n;
        for (int ch = 0; ch < 3; ++ch) normal->at(ch, row, col) = static_cast<float>(levelled(ch));
      }
    }
  });
  double lo = std::numeric_limits<double>::infinity(), hi = -lo, tilt = 0.0;
  for (int r = 0; r < h; ++r) {
    lo = std::min(lo, row_lo[static_cast<std::size_t>(r)]);
    hi = std::max(hi, row_hi[static_cast<std::size_t>(r)]);
    tilt = std::max(tilt, row_tilt[static_cast<std::size_t>(r)]);
  }
  result.peak_to_valley_mm = hi >= lo ? hi - lo : 0.0;
  result.max_tilt_deg = std::atan(tilt) * 180.0 / std::numbers::pi;
  return result;
}

}  // namespace u3mscan::reconstruction
