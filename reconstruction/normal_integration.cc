#include "reconstruction/normal_integration.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>
#include <stdexcept>
#include <unsupported/Eigen/FFT>
#include <vector>

#include "core/logging.h"
#include "core/parallel.h"

namespace u3mscan::reconstruction {

std::string IntegratorName(Integrator integrator) { return integrator == Integrator::kDct ? "dct" : "robust"; }

Integrator ParseIntegrator(const std::string& name) {
  if (name == "dct") return Integrator::kDct;
  if (name == "robust") return Integrator::kRobust;
  throw std::invalid_argument("integrator must be dct or robust, got '" + name + "'");
}

bool IntegrationOptions::Check() const {
  return pitch_mm >= 0.0 && std::isfinite(pitch_mm) && min_normal_z > 0.0 && min_normal_z < 1.0 &&
         std::isfinite(mean_height_mm) && robust_iterations >= 0 && min_residual_slope > 0.0 &&
         min_edge_weight > 0.0 && min_edge_weight <= 1.0 && cg_tolerance > 0.0 && robust_round_cg_tolerance > 0.0 &&
         settled_edge_fraction >= 0.0 && max_cg_iterations > 0 &&
         (!parallax.enabled || (parallax.camera_z_mm - parallax.plane_z_mm > 0.0 && parallax.min_stretch > 0.0 &&
                                parallax.min_stretch <= 1.0 && std::isfinite(parallax.camera_x_mm) &&
                                std::isfinite(parallax.camera_y_mm) && std::isfinite(parallax.x0_mm) &&
                                std::isfinite(parallax.y1_mm)));
}

double ParallaxStretch(const ViewParallax& parallax, double pitch_mm, int col, int row, double slope_x, double slope_y) {
  if (!parallax.enabled) return 1.0;
  const double x = parallax.x0_mm + (static_cast<double>(col) + 0.5) * pitch_mm;
  const double y = parallax.y1_mm - (static_cast<double>(row) + 0.5) * pitch_mm;
  const double depth = parallax.camera_z_mm - parallax.plane_z_mm;
  const double tx = (parallax.camera_x_mm - x) / depth, ty = (parallax.camera_y_mm - y) / depth;
  return std::max(1.0 - (slope_x * tx + slope_y * ty), parallax.min_stretch);
}

namespace {

// Lengths whose prime factors are all at most this go straight to kissfft; longer prime factors
// take Bluestein's detour (ComplexFft) or, in the PCG preconditioner, a padded length.
constexpr int kSmallPrime = 13;

int LargestPrimeFactor(int n) {
  int largest = 1;
  for (int p = 2; static_cast<long long>(p) * p <= n; ++p)
    while (n % p == 0) largest = p, n /= p;
  return std::max(largest, n);
}

// Complex FFT of one length. Eigen's FFT (kissfft) is fast for lengths made of small primes but
// O(n p) for a large prime factor p; such lengths (e.g. 3543 = 3 x 1181 pixels) go through
// Bluestein's chirp-z algorithm: a circular convolution of power-of-two length >= 2n - 1.
class ComplexFft {
 public:
  explicit ComplexFft(int n) : n_(n) {
    if (LargestPrimeFactor(n) <= kSmallPrime) return;
    m_ = 1;
    while (m_ < 2 * n - 1) m_ *= 2;
    chirp_.resize(n);
    for (int k = 0; k < n; ++k) {
      // exp(-i pi k^2 / n), with k^2 reduced mod 2n so the angle stays exact for long lines.
      const long long k2 = (static_cast<long long>(k) * k) % (2LL * n);
      chirp_[k] = std::polar(1.0, -std::numbers::pi * static_cast<double>(k2) / n);
    }
    std::vector<std::complex<double>> b(m_, 0.0);
    b[0] = std::conj(chirp_[0]);
    for (int k = 1; k < n; ++k) b[k] = b[m_ - k] = std::conj(chirp_[k]);
    kernel_.resize(m_);
    fft_.fwd(kernel_.data(), b.data(), m_);
    work_.resize(m_);
    spectrum_.resize(m_);
  }

  void Forward(std::complex<double>* out, const std::complex<double>* in) {
    if (m_ == 0) {
      fft_.fwd(out, in, n_);
      return;
    }
    std::fill(work_.begin(), work_.end(), 0.0);
    for (int k = 0; k < n_; ++k) work_[k] = in[k] * chirp_[k];
    fft_.fwd(spectrum_.data(), work_.data(), m_);
    for (int k = 0; k < m_; ++k) spectrum_[k] *= kernel_[k];
    fft_.inv(work_.data(), spectrum_.data(), m_);
    for (int k = 0; k < n_; ++k) out[k] = work_[k] * chirp_[k];
  }

  // Inverse with 1/n scaling, through the forward transform of the conjugate.
  void Inverse(std::complex<double>* out, const std::complex<double>* in) {
    if (m_ == 0) {
      fft_.inv(out, in, n_);
      return;
    }
    for (int k = 0; k < n_; ++k) out[k] = std::conj(in[k]);
    Forward(out, out);
    for (int k = 0; k < n_; ++k) out[k] = std::conj(out[k]) / static_cast<double>(n_);
  }

 private:
  int n_;
  int m_ = 0;  // Bluestein length; 0 = direct
  Eigen::FFT<double> fft_;
  std::vector<std::complex<double>> chirp_, kernel_, work_, spectrum_;
};

// DCT-II / its inverse along one line of length n via a complex FFT of length n (Makhoul 1980):
// v = (x0, x2, x4, ..., x5, x3, x1), X_k = Re(exp(-i pi k / 2n) FFT(v)_k). Two real lines a, b go
// through one complex FFT of a + i b (Forward/InversePair), halving the FFT work of a 2-D
// transform. Buffers are allocated once per plan, so a plan serves every line of a chunk without
// allocation.
class DctPlan {
 public:
  explicit DctPlan(int n) : n_(n), fft_(n), in_(n), out_(n), twiddle_(n) {
    for (int k = 0; k < n; ++k) twiddle_[k] = std::polar(1.0, -std::numbers::pi * k / (2.0 * n));
  }

  void Forward(double* x) {
    if (n_ <= 1) return;
    Reorder(x, nullptr);
    fft_.Forward(out_.data(), in_.data());
    for (int k = 0; k < n_; ++k) x[k] = (twiddle_[k] * out_[k]).real();
  }

  // Forward of two lines at once: C = FFT(va + i vb) splits into the spectra of the real
  // sequences, A_k = (C_k + conj C_{n-k}) / 2 and B_k = (C_k - conj C_{n-k}) / 2i.
  void ForwardPair(double* a, double* b) {
    if (n_ <= 1) return;
    Reorder(a, b);
    fft_.Forward(out_.data(), in_.data());
    for (int k = 0; k < n_; ++k) {
      const std::complex<double> c = out_[k], c_mirror = std::conj(out_[k == 0 ? 0 : n_ - k]);
      const std::complex<double> spectrum_a = 0.5 * (c + c_mirror);
      const std::complex<double> spectrum_b = std::complex<double>(0.0, -0.5) * (c - c_mirror);
      a[k] = (twiddle_[k] * spectrum_a).real();
      b[k] = (twiddle_[k] * spectrum_b).real();
    }
  }

  // Exact inverse of Forward: V_k = exp(i pi k / 2n) (X_k - i X_{n-k}), X_n = 0, then IFFT.
  void Inverse(double* x) {
    if (n_ <= 1) return;
    for (int k = 0; k < n_; ++k) in_[k] = Spectrum(x, k);
    fft_.Inverse(out_.data(), in_.data());
    Restore(x, nullptr);
  }

  // Inverse of two lines at once: each V gives a real sequence, so IFFT(Va + i Vb) = va + i vb.
  void InversePair(double* a, double* b) {
    if (n_ <= 1) return;
    for (int k = 0; k < n_; ++k) in_[k] = Spectrum(a, k) + std::complex<double>(0.0, 1.0) * Spectrum(b, k);
    fft_.Inverse(out_.data(), in_.data());
    Restore(a, b);
  }

  // Forward or inverse of line a, and of line b with it when b is not null.
  void Transform(double* a, double* b, bool forward) {
    if (b) {
      forward ? ForwardPair(a, b) : InversePair(a, b);
    } else {
      forward ? Forward(a) : Inverse(a);
    }
  }

 private:
  // in_ = va (+ i vb): the even samples forward, then the odd ones backward.
  void Reorder(const double* a, const double* b) {
    const int half = (n_ + 1) / 2;
    for (int i = 0; i < half; ++i) in_[i] = {a[2 * i], b ? b[2 * i] : 0.0};
    for (int i = 0; 2 * i + 1 < n_; ++i) in_[n_ - 1 - i] = {a[2 * i + 1], b ? b[2 * i + 1] : 0.0};
  }
  // The reverse of Reorder from out_: a from the real parts, b from the imaginary parts.
  void Restore(double* a, double* b) const {
    const int half = (n_ + 1) / 2;
    for (int i = 0; i < half; ++i) {
      a[2 * i] = out_[i].real();
      if (b) b[2 * i] = out_[i].imag();
    }
    for (int i = 0; 2 * i + 1 < n_; ++i) {
      a[2 * i + 1] = out_[n_ - 1 - i].real();
      if (b) b[2 * i + 1] = out_[n_ - 1 - i].imag();
    }
  }
  std::complex<double> Spectrum(const double* x, int k) const {
    const double x_mirror = k == 0 ? 0.0 : x[n_ - k];
    return std::conj(twiddle_[k]) * std::complex<double>(x[k], -x_mirror);
  }

  int n_;
  ComplexFft fft_;
  std::vector<std::complex<double>> in_, out_, twiddle_;
};

}  // namespace

namespace internal {
// Smallest m >= n whose prime factors are 2, 3 and 5 only: kissfft's fast radices.
int SmoothLength(int n) {
  for (int m = std::max(n, 1);; ++m) {
    int k = m;
    for (int p : {2, 3, 5})
      while (k % p == 0) k /= p;
    if (k == 1) return m;
  }
}
}  // namespace internal

namespace {
using internal::SmoothLength;

// Solves L u = f for the unweighted 4-neighbour graph Laplacian of a W x H grid with natural
// (Neumann) boundary: L is diagonalised by the 2-D DCT-II with eigenvalues
// (2 - 2 cos(pi kx / W)) + (2 - 2 cos(pi ky / H)). The constant (kx = ky = 0) is set to zero.
//
// Exact (pad = false): W x H is the map, u = L^+ f. Padded (pad = true): a map side with a prime
// factor above kSmallPrime becomes the next 2-3-5-smooth length (5520 x 3684 -> 5625 x 3750), f is
// zero-padded on the right and bottom, and u is the crop: u = E^T L_pad^+ E f with E the
// zero-padding. That is symmetric and positive definite (E f is never a non-zero constant once a
// pad exists), so it is a valid PCG preconditioner and the CG answer does not change, only the
// iteration count; but it is not the exact solve. Why: such lengths (3684 = 2^2 3 307) go through
// Bluestein's transform, several times slower per pixel than a smooth length, once per iteration.
// (A mirrored pad, E reflecting f, was tried: 178 instead of 44 iterations on 307 x 211.)
class PoissonDctSolver {
 public:
  PoissonDctSolver(int width, int height, bool pad)
      : map_width_(width),
        map_height_(height),
        width_(pad ? PaddedLength(width) : width),
        height_(pad ? PaddedLength(height) : height),
        eig_x_(width_),
        eig_y_(height_) {
    for (int k = 0; k < width_; ++k) eig_x_[k] = 2.0 - 2.0 * std::cos(std::numbers::pi * k / width_);
    for (int k = 0; k < height_; ++k) eig_y_[k] = 2.0 - 2.0 * std::cos(std::numbers::pi * k / height_);
  }

  // Only lengths that would take Bluestein's detour are padded: on a 13-smooth map the
  // preconditioner stays the exact Poisson solve (padding costs PCG iterations: 307 x 211 with a
  // mask needs 44 instead of 17, 1380 x 921 11 instead of 9).
  static int PaddedLength(int n) { return LargestPrimeFactor(n) > kSmallPrime ? SmoothLength(n) : n; }

  bool padded() const { return width_ != map_width_ || height_ != map_height_; }

  // values: the map (map_width x map_height, row-major), replaced by the solution.
  void Solve(std::vector<double>& values) {
    if (!padded()) {
      SolveGrid(values);
      return;
    }
    // One padded plane, kept between calls (PCG calls this once per iteration).
    grid_.assign(static_cast<std::size_t>(width_) * height_, 0.0);
    ParallelFor(map_height_, [&](std::size_t r0, std::size_t r1) {
      for (std::size_t r = r0; r < r1; ++r)
        std::copy_n(values.data() + r * map_width_, map_width_, grid_.data() + r * width_);
    });
    SolveGrid(grid_);
    ParallelFor(map_height_, [&](std::size_t r0, std::size_t r1) {
      for (std::size_t r = r0; r < r1; ++r)
        std::copy_n(grid_.data() + r * width_, map_width_, values.data() + r * map_width_);
    });
  }

 private:
  void SolveGrid(std::vector<double>& values) const {
    TransformRows(values, true);
    TransformColumns(values, true);
    ParallelFor(height_, [&](std::size_t begin, std::size_t end) {
      for (std::size_t r = begin; r < end; ++r) {
        double* row = values.data() + r * width_;
        for (int c = 0; c < width_; ++c) {
          const double eig = eig_x_[c] + eig_y_[r];
          row[c] = eig > 0.0 ? row[c] / eig : 0.0;
        }
      }
    });
    TransformColumns(values, false);
    TransformRows(values, false);
  }

  void TransformRows(std::vector<double>& values, bool forward) const {
    // Rows in pairs (one complex FFT per pair); a leftover odd row alone.
    const std::size_t pairs = (height_ + 1) / 2;
    ParallelFor(pairs, [&](std::size_t begin, std::size_t end) {
      DctPlan plan(width_);
      for (std::size_t p = begin; p < end; ++p) {
        double* a = values.data() + 2 * p * width_;
        plan.Transform(a, 2 * p + 1 < static_cast<std::size_t>(height_) ? a + width_ : nullptr, forward);
      }
    });
  }

  // Columns in blocks of kBlock so the strided gather touches whole cache lines.
  void TransformColumns(std::vector<double>& values, bool forward) const {
    constexpr int kBlock = 8;
    const std::size_t blocks = (width_ + kBlock - 1) / kBlock;
    ParallelFor(blocks, [&](std::size_t begin, std::size_t end) {
      DctPlan plan(height_);
      std::vector<double> column(static_cast<std::size_t>(height_) * kBlock);
      for (std::size_t b = begin; b < end; ++b) {
        const int c0 = static_cast<int>(b) * kBlock;
        const int nc = std::min(kBlock, width_ - c0);
        for (int r = 0; r < height_; ++r)
          for (int j = 0; j < nc; ++j) column[j * height_ + r] = values[static_cast<std::size_t>(r) * width_ + c0 + j];
        for (int j = 0; j < nc; j += 2) {
          double* a = &column[j * height_];
          plan.Transform(a, j + 1 < nc ? a + height_ : nullptr, forward);
        }
        for (int r = 0; r < height_; ++r)
          for (int j = 0; j < nc; ++j) values[static_cast<std::size_t>(r) * width_ + c0 + j] = column[j * height_ + r];
      }
    });
  }

  int map_width_, map_height_;
  int width_, height_;  // of the solved grid
  std::vector<double> eig_x_, eig_y_;
  std::vector<double> grid_;  // padded plane (padded solvers only)
};

// The edges of the grid: horizontal edge (r, c) -> (r, c + 1) stored at r * w + c (c < w - 1),
// vertical edge (r, c) -> (r + 1, c) stored at r * w + c (r < h - 1). target: expected z_j - z_i
// in mm; weight: w_e of the least-squares energy; base: the mask weight of the edge (0 = cut).
struct EdgeField {
  int width = 0, height = 0;
  std::vector<float> target_x, target_y, weight_x, weight_y, base_x, base_y;
};

// Deterministic parallel sum over blocks.
template <typename F>
double ParallelSum(std::size_t count, F term) {
  constexpr std::size_t kBlocks = 64;
  std::vector<double> partial(kBlocks, 0.0);
  ParallelFor(kBlocks, [&](std::size_t b0, std::size_t b1) {
    for (std::size_t b = b0; b < b1; ++b) {
      const std::size_t begin = count * b / kBlocks, end = count * (b + 1) / kBlocks;
      double s = 0.0;
      for (std::size_t i = begin; i < end; ++i) s += term(i);
      partial[b] = s;
    }
  });
  double total = 0.0;
  for (double s : partial) total += s;
  return total;
}

// out = A z with A = sum_e w_e (e_i - e_j)(e_i - e_j)^T (weighted graph Laplacian), matrix-free.
void ApplyLaplacian(const EdgeField& e, const std::vector<double>& z, std::vector<double>& out) {
  const int w = e.width, h = e.height;
  ParallelFor(h, [&](std::size_t begin, std::size_t end) {
    for (std::size_t rr = begin; rr < end; ++rr) {
      const int r = static_cast<int>(rr);
      for (int c = 0; c < w; ++c) {
        const std::size_t i = static_cast<std::size_t>(r) * w + c;
        double s = 0.0;
        if (c + 1 < w) s += e.weight_x[i] * (z[i] - z[i + 1]);
        if (c > 0) s += e.weight_x[i - 1] * (z[i] - z[i - 1]);
        if (r + 1 < h) s += e.weight_y[i] * (z[i] - z[i + w]);
        if (r > 0) s += e.weight_y[i - w] * (z[i] - z[i - w]);
        out[i] = s;
      }
    }
  });
}

// b_i = sum over edges ending at i of w t - sum over edges starting at i of w t.
void BuildRightHandSide(const EdgeField& e, bool unit_weights, std::vector<double>& b) {
  const int w = e.width, h = e.height;
  ParallelFor(h, [&](std::size_t begin, std::size_t end) {
    for (std::size_t rr = begin; rr < end; ++rr) {
      const int r = static_cast<int>(rr);
      for (int c = 0; c < w; ++c) {
        const std::size_t i = static_cast<std::size_t>(r) * w + c;
        auto wt_x = [&](std::size_t k) { return (unit_weights ? 1.0 : e.weight_x[k]) * e.target_x[k]; };
        auto wt_y = [&](std::size_t k) { return (unit_weights ? 1.0 : e.weight_y[k]) * e.target_y[k]; };
        double s = 0.0;
        if (c + 1 < w) s -= wt_x(i);
        if (c > 0) s += wt_x(i - 1);
        if (r + 1 < h) s -= wt_y(i);
        if (r > 0) s += wt_y(i - w);
        b[i] = s;
      }
    }
  });
}

void RemoveMean(std::vector<double>& v) {
  const double mean = ParallelSum(v.size(), [&](std::size_t i) { return v[i]; }) / v.size();
  ParallelFor(v.size(), [&](std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) v[i] -= mean;
  });
}

// Preconditioned conjugate gradients on A z = b (A singular with the constants as null space; b
// sums to zero). A padded preconditioner may add a constant to z; A ignores it and the result is
// anchored by its mean afterwards. Returns iterations; *relative_residual gets |b - Az| / |b|.
int SolvePcg(const EdgeField& e, PoissonDctSolver& precond, const std::vector<double>& b,
             std::vector<double>& z, double tolerance, int max_iterations, double* relative_residual) {
  const std::size_t n = b.size();
  std::vector<double> r(n), s(n), p(n), ap(n);
  ApplyLaplacian(e, z, ap);
  ParallelFor(n, [&](std::size_t i0, std::size_t i1) {
    for (std::size_t i = i0; i < i1; ++i) r[i] = b[i] - ap[i];
  });
  const double b_norm = std::sqrt(ParallelSum(n, [&](std::size_t i) { return b[i] * b[i]; }));
  if (b_norm == 0.0) {
    *relative_residual = 0.0;
    return 0;
  }
  double r_norm = std::sqrt(ParallelSum(n, [&](std::size_t i) { return r[i] * r[i]; }));
  *relative_residual = r_norm / b_norm;
  if (*relative_residual <= tolerance) return 0;
  s = r;
  precond.Solve(s);
  p = s;
  double rs = ParallelSum(n, [&](std::size_t i) { return r[i] * s[i]; });
  int it = 0;
  while (it < max_iterations) {
    ++it;
    ApplyLaplacian(e, p, ap);
    const double pap = ParallelSum(n, [&](std::size_t i) { return p[i] * ap[i]; });
    if (!(pap > 0.0)) break;
    const double alpha = rs / pap;
    ParallelFor(n, [&](std::size_t i0, std::size_t i1) {
      for (std::size_t i = i0; i < i1; ++i) {
        z[i] += alpha * p[i];
        r[i] -= alpha * ap[i];
      }
    });
    r_norm = std::sqrt(ParallelSum(n, [&](std::size_t i) { return r[i] * r[i]; }));
    *relative_residual = r_norm / b_norm;
    if (*relative_residual <= tolerance) break;
    s = r;
    precond.Solve(s);
    const double rs_new = ParallelSum(n, [&](std::size_t i) { return r[i] * s[i]; });
    const double beta = rs_new / rs;
    rs = rs_new;
    ParallelFor(n, [&](std::size_t i0, std::size_t i1) {
      for (std::size_t i = i0; i < i1; ++i) p[i] = s[i] + beta * p[i];
    });
  }
  return it;
}

// Median of |x| (reorders the values), for the robust residual scale.
double MedianAbs(std::vector<float>& values) {
  if (values.empty()) return 0.0;
  for (float& v : values) v = std::fabs(v);
  auto mid = values.begin() + values.size() / 2;
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

// 2x2 block means: normals (weighted by the mask, renormalised) and mask; the pitch doubles.
void Downsample(const Image& normal, const Image& mask, double pitch_mm, Image* coarse_normal, Image* coarse_mask) {
  const int w = normal.width(), h = normal.height();
  const int cw = (w + 1) / 2, ch = (h + 1) / 2;
  const std::size_t n = normal.pixel_count(), cn = static_cast<std::size_t>(cw) * ch;
  *coarse_normal = Image(cw, ch, 3, 0.0f, 2.0 * pitch_mm);
  *coarse_mask = Image(cw, ch, 1, 0.0f, 2.0 * pitch_mm);
  ParallelFor(ch, [&](std::size_t r0, std::size_t r1) {
    for (std::size_t cr = r0; cr < r1; ++cr)
      for (int cc = 0; cc < cw; ++cc) {
        double sum[3] = {0, 0, 0}, wsum = 0.0;
        int count = 0;
        for (int dr = 0; dr < 2; ++dr)
          for (int dc = 0; dc < 2; ++dc) {
            const int r = 2 * static_cast<int>(cr) + dr, c = 2 * cc + dc;
            if (r >= h || c >= w) continue;
            ++count;
            const std::size_t i = static_cast<std::size_t>(r) * w + c;
            double wt = mask.empty() ? 1.0 : mask.data()[i];
            const double v[3] = {normal.data()[i], normal.data()[n + i], normal.data()[2 * n + i]};
            if (!(wt > 0.0) || !std::isfinite(v[0] + v[1] + v[2])) continue;
            wt = std::min(wt, 1.0);
            for (int k = 0; k < 3; ++k) sum[k] += wt * v[k];
            wsum += wt;
          }
        const std::size_t j = cr * cw + cc;
        const double len = std::sqrt(sum[0] * sum[0] + sum[1] * sum[1] + sum[2] * sum[2]);
        if (wsum > 0.0 && len > 0.0) {
          for (int k = 0; k < 3; ++k) coarse_normal->data()[k * cn + j] = static_cast<float>(sum[k] / len);
          coarse_mask->data()[j] = static_cast<float>(wsum / count);
        } else {
          coarse_normal->data()[2 * cn + j] = 1.0f;
        }
      }
  });
}

// Bilinear upsampling of coarse heights onto the w x h grid (fine pixel c sits at coarse c/2 - 1/4).
void Upsample(const Image& coarse, int w, int h, std::vector<double>& z) {
  const int cw = coarse.width(), ch = coarse.height();
  auto at = [&](int r, int c) {
    return static_cast<double>(coarse.data()[static_cast<std::size_t>(std::clamp(r, 0, ch - 1)) * cw + std::clamp(c, 0, cw - 1)]);
  };
  ParallelFor(h, [&](std::size_t r0, std::size_t r1) {
    for (std::size_t r = r0; r < r1; ++r) {
      const double y = 0.5 * static_cast<double>(r) - 0.25;
      const int y0 = static_cast<int>(std::floor(y));
      const double fy = y - y0;
      for (int c = 0; c < w; ++c) {
        const double x = 0.5 * c - 0.25;
        const int x0 = static_cast<int>(std::floor(x));
        const double fx = x - x0;
        z[r * w + c] = (1 - fy) * ((1 - fx) * at(y0, x0) + fx * at(y0, x0 + 1)) +
                       fy * ((1 - fx) * at(y0 + 1, x0) + fx * at(y0 + 1, x0 + 1));
      }
    }
  });
}

}  // namespace

namespace internal {
void DctLine(double* values, int n) { DctPlan(n).Forward(values); }
void InverseDctLine(double* values, int n) { DctPlan(n).Inverse(values); }
void DctLinePair(double* a, double* b, int n) { DctPlan(n).ForwardPair(a, b); }
void InverseDctLinePair(double* a, double* b, int n) { DctPlan(n).InversePair(a, b); }
}  // namespace internal

IntegrationResult IntegrateNormals(const Image& normal, const Image& mask, const IntegrationOptions& options,
                                   const ProgressCallback& progress) {
  if (!options.Check()) throw std::invalid_argument("IntegrateNormals: options fail Check()");
  if (normal.channels() != 3) throw std::invalid_argument("IntegrateNormals: normal map needs 3 channels");
  const int w = normal.width(), h = normal.height();
  if (w <= 0 || h <= 0) throw std::invalid_argument("IntegrateNormals: empty normal map");
  if (!mask.empty() && (mask.width() != w || mask.height() != h))
    throw std::invalid_argument("IntegrateNormals: mask size differs from the normal map");
  const double pitch_mm = options.pitch_mm > 0.0 ? options.pitch_mm : normal.pitch_mm();
  if (!(pitch_mm > 0.0)) throw std::invalid_argument("IntegrateNormals: pixel pitch unknown (set pitch_mm)");

  const std::size_t n = normal.pixel_count();
  // Per-pixel slopes (mm per mm) and weights; invalid pixels get weight 0.
  std::vector<float> slope_x(n), slope_y(n), pixel_weight(n);
  const double m = options.min_normal_z;
  const double max_tangent = std::sqrt(1.0 - m * m);
  const ViewParallax& parallax = options.parallax;
  ParallelFor(n, [&](std::size_t i0, std::size_t i1) {
    for (std::size_t i = i0; i < i1; ++i) {
      double nx = normal.data()[i], ny = normal.data()[n + i], nz = normal.data()[2 * n + i];
      double wgt = 1.0;
      if (!mask.empty()) {
        const float mv = mask.data()[i];
        wgt = std::isfinite(mv) ? std::clamp(static_cast<double>(mv), 0.0, 1.0) : 0.0;
      }
      const double len = std::sqrt(nx * nx + ny * ny + nz * nz);
      if (!std::isfinite(len) || len < 1e-12) {
        slope_x[i] = slope_y[i] = 0.0f;
        pixel_weight[i] = 0.0f;
        continue;
      }
      nx /= len, ny /= len, nz /= len;
      if (nz < m) {  // grazing or facing away: keep the azimuth, clamp the tilt
        const double t = std::sqrt(nx * nx + ny * ny);
        if (t > 0.0) nx *= max_tangent / t, ny *= max_tangent / t;
        nz = m;
      }
      double sx = -nx / nz, sy = -ny / nz;
      if (parallax.enabled) {
        // The grid's slope of a surface seen along oblique rays (ViewParallax).
        const double stretch = ParallaxStretch(parallax, pitch_mm, static_cast<int>(i % w), static_cast<int>(i / w), sx, sy);
        sx /= stretch, sy /= stretch;
      }
      slope_x[i] = static_cast<float>(sx);
      slope_y[i] = static_cast<float>(sy);
      pixel_weight[i] = static_cast<float>(wgt);
    }
  });

  EdgeField e;
  e.width = w, e.height = h;
  for (auto* v : {&e.target_x, &e.target_y, &e.weight_x, &e.weight_y, &e.base_x, &e.base_y}) v->assign(n, 0.0f);
  bool all_unit = true;
  ParallelFor(h, [&](std::size_t begin, std::size_t end) {
    for (std::size_t rr = begin; rr < end; ++rr) {
      const int r = static_cast<int>(rr);
      for (int c = 0; c < w; ++c) {
        const std::size_t i = static_cast<std::size_t>(r) * w + c;
        if (c + 1 < w) {
          const float base = std::min(pixel_weight[i], pixel_weight[i + 1]);
          e.base_x[i] = base;
          // Columns grow with +x: z(c + 1) - z(c) = p dz/dx.
          e.target_x[i] = base > 0.0f ? static_cast<float>(0.5 * pitch_mm * (slope_x[i] + slope_x[i + 1])) : 0.0f;
        }
        if (r + 1 < h) {
          const float base = std::min(pixel_weight[i], pixel_weight[i + w]);
          e.base_y[i] = base;
          // Rows grow with -y: z(r + 1) - z(r) = -p dz/dy.
          e.target_y[i] = base > 0.0f ? static_cast<float>(-0.5 * pitch_mm * (slope_y[i] + slope_y[i + w])) : 0.0f;
        }
      }
    }
  });
  for (std::size_t i = 0; i < n && all_unit; ++i) all_unit = pixel_weight[i] == 1.0f;
  slope_x = {};
  slope_y = {};

  const float min_w = static_cast<float>(options.min_edge_weight);
  auto set_weights_from_base = [&] {
    for (std::size_t i = 0; i < n; ++i) {
      e.weight_x[i] = std::max(e.base_x[i], min_w);
      e.weight_y[i] = std::max(e.base_y[i], min_w);
    }
  };
  set_weights_from_base();

  IntegrationResult result;
  // The exact solve runs once (the start, and the whole answer for kDct without a mask): it stays
  // on the map's own size, Bluestein or not. PCG calls its preconditioner every iteration: that
  // one runs on the padded smooth size (see PoissonDctSolver).
  PoissonDctSolver dct(w, h, /*pad=*/false);
  PoissonDctSolver precond(w, h, /*pad=*/true);
  std::vector<double> z(n), b(n);
  const bool coarse_start = options.method == Integrator::kRobust && options.multiscale &&
                            std::min(w, h) >= 2 * IntegrationOptions::kCoarsestSide;
  if (coarse_start) {
    // Coarse to fine: the robust solve of the half-size map puts the discontinuities in place, so
    // the rounds here only sharpen them (a cut found by reweighting alone grows a few pixels per
    // round).
    Image coarse_normal, coarse_mask;
    Downsample(normal, mask, pitch_mm, &coarse_normal, &coarse_mask);
    IntegrationOptions coarse_options = options;
    coarse_options.pitch_mm = 2.0 * pitch_mm;
    const IntegrationResult coarse = IntegrateNormals(coarse_normal, coarse_mask, coarse_options);
    result.cg_iterations += coarse.cg_iterations;
    Upsample(coarse.height_mm, w, h, z);
    ReportProgress(progress, "integration", 0.25);
  } else {
    // Start: the exact unweighted solve (the whole answer for kDct without a mask).
    BuildRightHandSide(e, /*unit_weights=*/true, b);
    z = b;
    dct.Solve(z);
    ReportProgress(progress, "integration", 0.1);
  }
  if (!all_unit && !coarse_start) {
    BuildRightHandSide(e, false, b);
    RemoveMean(b);
    result.cg_iterations += SolvePcg(e, precond, b, z, options.cg_tolerance, options.max_cg_iterations,
                                     &result.relative_residual);
  }

  // Robust weights per edge; left empty (all 1) for kDct.
  std::vector<float> robust_x, robust_y;
  if (options.method == Integrator::kRobust) {
    robust_x.assign(n, 1.0f);
    robust_y.assign(n, 1.0f);
    // The residual scale from a bounded sample of the in-region edges (every stride-th pixel), so
    // no plane of residuals is stored; the weights are then updated in parallel over rows.
    constexpr std::size_t kMaxSamples = 1u << 20;
    const std::size_t stride = std::max<std::size_t>(1, 2 * n / kMaxSamples);
    std::vector<float> sample;
    sample.reserve(2 * n / stride + 2);
    // Per row: edges whose weight moved by more than kWeightStep this round.
    constexpr float kWeightStep = 0.01f;
    std::vector<std::size_t> row_changed(h);
    for (int round = 0; round < options.robust_iterations; ++round) {
      sample.clear();
      for (std::size_t i = 0; i < n; i += stride) {
        const int r = static_cast<int>(i / w), c = static_cast<int>(i % w);
        if (c + 1 < w && e.base_x[i] > 0.0f) sample.push_back(static_cast<float>(z[i + 1] - z[i] - e.target_x[i]));
        if (r + 1 < h && e.base_y[i] > 0.0f) sample.push_back(static_cast<float>(z[i + w] - z[i] - e.target_y[i]));
      }
      const double sigma = std::max(kMadToSigma * MedianAbs(sample), options.min_residual_slope * pitch_mm);
      ParallelFor(h, [&](std::size_t r0, std::size_t r1) {
        for (std::size_t rr = r0; rr < r1; ++rr) {
          const int r = static_cast<int>(rr);
          std::size_t changed = 0;
          for (int c = 0; c < w; ++c) {
            const std::size_t i = static_cast<std::size_t>(r) * w + c;
            if (c + 1 < w) {
              const float rw = static_cast<float>(RobustWeight(options.loss, z[i + 1] - z[i] - e.target_x[i], sigma));
              changed += std::fabs(rw - robust_x[i]) > kWeightStep;
              robust_x[i] = rw;
              e.weight_x[i] = std::max(e.base_x[i] * rw, min_w);
            }
            if (r + 1 < h) {
              const float rw = static_cast<float>(RobustWeight(options.loss, z[i + w] - z[i] - e.target_y[i], sigma));
              changed += std::fabs(rw - robust_y[i]) > kWeightStep;
              robust_y[i] = rw;
              e.weight_y[i] = std::max(e.base_y[i] * rw, min_w);
            }
          }
          row_changed[rr] = changed;
        }
      });
      std::size_t changed = 0;
      for (std::size_t c : row_changed) changed += c;
      ++result.robust_iterations;
      // Weights settled (at most 1e-4 of the edges still moving): the final solve follows.
      if (round > 0 && static_cast<double>(changed) <= options.settled_edge_fraction * 2.0 * static_cast<double>(n)) break;
      BuildRightHandSide(e, false, b);
      RemoveMean(b);
      // Rounds only need heights good enough to reweigh; the last system is solved tightly below.
      result.cg_iterations += SolvePcg(e, precond, b, z, std::max(options.cg_tolerance, options.robust_round_cg_tolerance),
                                       options.max_cg_iterations, &result.relative_residual);
      ReportProgress(progress, "integration", 0.1 + 0.85 * (round + 1) / options.robust_iterations);
    }
    BuildRightHandSide(e, false, b);
    RemoveMean(b);
    result.cg_iterations += SolvePcg(e, precond, b, z, options.cg_tolerance, options.max_cg_iterations,
                                     &result.relative_residual);
  }

  // Anchor: mean over the valid pixels.
  double sum = 0.0, count = 0.0;
  for (std::size_t i = 0; i < n; ++i)
    if (pixel_weight[i] > 0.0f) sum += z[i], count += 1.0;
  const double shift = options.mean_height_mm - (count > 0.0 ? sum / count : 0.0);

  result.height_mm = Image(w, h, 1, 0.0f, pitch_mm);
  result.edge_confidence = Image(w, h, 1, 0.0f, pitch_mm);
  float* out = result.height_mm.data().data();
  float* conf = result.edge_confidence.data().data();
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c) {
      const std::size_t i = static_cast<std::size_t>(r) * w + c;
      const double v = z[i] + shift;
      out[i] = std::isfinite(v) ? static_cast<float>(v) : static_cast<float>(options.mean_height_mm);
      if (pixel_weight[i] <= 0.0f) continue;
      float cmin = 1.0f;
      if (!robust_x.empty()) {
        if (c + 1 < w && e.base_x[i] > 0.0f) cmin = std::min(cmin, robust_x[i]);
        if (c > 0 && e.base_x[i - 1] > 0.0f) cmin = std::min(cmin, robust_x[i - 1]);
        if (r + 1 < h && e.base_y[i] > 0.0f) cmin = std::min(cmin, robust_y[i]);
        if (r > 0 && e.base_y[i - w] > 0.0f) cmin = std::min(cmin, robust_y[i - w]);
      }
      conf[i] = cmin * pixel_weight[i];
    }
  LogDebug() << "integration " << IntegratorName(options.method) << " " << w << "x" << h << ": "
             << result.robust_iterations << " robust rounds, " << result.cg_iterations
             << " CG iterations (incl. coarser levels), relative residual " << result.relative_residual;
  ReportProgress(progress, "integration", 1.0);
  return result;
}

}  // namespace u3mscan::reconstruction
