#pragma once
// Normal integration: a unit normal map (world frame) -> a height map in millimetres.
//
// Frames and units (docs/capture-format.md): columns grow with +x, rows grow with -y, +z points out
// of the fabric toward the camera; the pixel pitch p (mm) comes from the metric grid. A normal
// n = (nx, ny, nz) gives the slopes dz/dx = -nx/nz and dz/dy = -ny/nz. Heights come out in mm,
// larger = further out of the surface, anchored so that their mean over the valid pixels is
// `IntegrationOptions::mean_height_mm` (integration fixes heights only up to a constant).
//
// Both integrators minimise sum_e w_e (z_j - z_i - t_e)^2 over the edges e = (i, j) between
// 4-neighbours, t_e = p * (mean slope of the two pixels along the edge):
//  - kDct: w_e = 1 on the whole rectangle: the Poisson equation with Neumann boundary, solved
//    exactly in O(n log n) with a 2-D DCT (Simchony, Chellappa and Shao 1990). With a mask, edges
//    leaving the valid region are cut and the system is solved by conjugate gradients
//    preconditioned with the same DCT solve.
//  - kRobust: IRLS on the edge residuals with a Cauchy or Tukey weight, each weighted system solved
//    matrix-free by DCT-preconditioned conjugate gradients, coarse to fine. Edges that disagree with
//    the surface (discontinuities: fabric edges, tears, holes, wrong normals) lose their weight, so
//    a jump stays where it is instead of being spread over the map.
// Speed: the conjugate gradients' preconditioner (the DCT Poisson solve) runs on the next
// 2-3-5-smooth size >= the map, zero-padded, because FFT lengths with a large prime factor are
// several times slower; the exact unmasked kDct solve stays on the map's size.
// Memory: no matrices. kDct without mask: 7 float and 2 double planes of the map size; a mask adds
// 4 double planes (CG) and one padded double plane (preconditioner; ~4 % larger than the map at
// 36 MP), kRobust 2 more float planes (robust weights) and its coarser levels (1/3 more). 36 MP
// DCT: ~1.6 GB plus input and output.

#include <string>

#include "core/image.h"
#include "core/progress.h"
#include "reconstruction/robust_loss.h"

namespace u3mscan::reconstruction {

enum class Integrator { kDct, kRobust };

// "dct" / "robust"; ParseIntegrator throws std::invalid_argument for another name.
std::string IntegratorName(Integrator integrator);
Integrator ParseIntegrator(const std::string& name);

// The camera the normals were seen from, for the parallax of its rays. A normal map rectified
// onto the plane z = plane_z_mm holds at grid point (x, y) the normal of the surface point its
// camera ray reaches, which lies (z - plane_z) t further toward the camera, t = the horizontal
// offset per unit height of the ray (camera - point).xy / (camera.z - plane_z). So the height's
// slope along the grid is g = s / (1 - s . t) for the surface's slope s = (-nx, -ny) / nz: facets
// that face the camera are stretched over more grid pixels. Integrating s instead leans the height
// toward the camera by about E[s^2] t, a bowl centred under it (docs/reconstruction.md,
// "Parallax of the view"). Off (the default): the rays are taken as vertical.
struct ViewParallax {
  bool enabled = false;
  double camera_x_mm = 0.0, camera_y_mm = 0.0, camera_z_mm = 0.0;  // the camera's centre, world frame
  // The map's left edge (x) and top edge (y), world mm: pixel (c, r) is centred at
  // (x0 + (c + 0.5) p, y1 - (r + 0.5) p); and the plane the map was rectified onto.
  double x0_mm = 0.0, y1_mm = 0.0, plane_z_mm = 0.0;
  // 1 - s . t is kept at least this: a facet seen nearly edge-on holds too few grid pixels to give
  // its slope (0.2: the slope grows at most 5x).
  double min_stretch = 0.2;
};

// The stretch 1 - s . t (ViewParallax) at the centre of pixel (col, row) of a map of pitch
// `pitch_mm` on the parallax's grid, for a surface of slope s = (slope_x, slope_y) (mm per mm),
// kept at least min_stretch; 1 when the parallax is off. A grid pixel holds 1 / stretch of its
// area of the surface's plan: the weight that turns a mean over grid pixels into the mean over the
// surface (pipeline/fine_grid.h AverageNormalsOntoMaps).
double ParallaxStretch(const ViewParallax& parallax, double pitch_mm, int col, int row, double slope_x, double slope_y);

struct IntegrationOptions {
  Integrator method = Integrator::kDct;
  ViewParallax parallax;
  // Pixel pitch in mm; 0 = take it from the normal map's Image::pitch_mm().
  double pitch_mm = 0.0;
  // Normals flatter than this n_z (or facing away) are clamped to it, bounding slopes at
  // sqrt(1 - m^2) / m (about 20 for the default): grazing normals carry no usable slope.
  double min_normal_z = 0.05;
  // Mean height over the valid pixels, mm.
  double mean_height_mm = 0.0;

  // kRobust: loss, number of reweighting rounds, and the residual scale sigma of the weights.
  // sigma = max(1.4826 * median |edge residual|, min_residual_slope * pitch_mm), so that
  // noise-free smooth surfaces (residuals ~ 0) keep unit weights.
  RobustLoss loss = RobustLoss::kCauchy;
  int robust_iterations = 30;
  // kRobust on maps of at least 2 * kCoarsestSide pixels a side: start from the robust solution
  // of the 2x2-averaged map (recursively), upsampled; without it a cut grows a few pixels per round.
  bool multiscale = true;
  static constexpr int kCoarsestSide = 64;
  double min_residual_slope = 0.02;
  // The rounds stop when at most this fraction of the edges changed weight by more than 0.01.
  double settled_edge_fraction = 1e-4;
  // No edge weight goes below this (keeps the system connected and conditioned).
  double min_edge_weight = 1e-4;

  // Conjugate gradients: stop at this relative residual |b - Az| / |b| or this many iterations.
  // The reweighting rounds of kRobust stop at the looser robust_round_cg_tolerance (their heights
  // only set the next weights); the final system is solved to cg_tolerance.
  double cg_tolerance = 1e-7;
  double robust_round_cg_tolerance = 1e-4;
  int max_cg_iterations = 400;

  bool Check() const;
};

struct IntegrationResult {
  Image height_mm;  // 1 channel, mm, same size and pitch as the normal map
  // Per-pixel confidence of the integration (1 channel, 0..1): the smallest weight of the edges at
  // the pixel after the robust rounds (1 everywhere for kDct without mask, 0 outside the mask).
  Image edge_confidence;
  int cg_iterations = 0;     // summed over all solves
  int robust_iterations = 0; // reweighting rounds run
  double relative_residual = 0.0;  // of the last linear solve
};

// normal: 3 channels, world frame, unit length (non-unit normals are normalised; non-finite ones
// count as invalid). mask: empty = every pixel valid; else 1 channel of per-pixel weights in 0..1,
// 0 = outside the region (its heights are a smooth fill and carry edge_confidence 0).
// Throws std::invalid_argument when sizes disagree, the pitch is unknown or options fail Check().
IntegrationResult IntegrateNormals(const Image& normal, const Image& mask, const IntegrationOptions& options,
                                   const ProgressCallback& progress = {});

namespace internal {
// Orthonormal-free DCT-II along one line (X_k = sum_n x_n cos(pi k (2n + 1) / 2N)) and its exact
// inverse, via one complex FFT of length N (Makhoul 1980). Exposed for tests.
void DctLine(double* values, int n);
void InverseDctLine(double* values, int n);
// The same for two lines a and b at once through one complex FFT of a + i b (what the 2-D
// transforms use).
void DctLinePair(double* a, double* b, int n);
void InverseDctLinePair(double* a, double* b, int n);
// Smallest length >= n with prime factors 2, 3 and 5 only: the padded preconditioner's sizes.
int SmoothLength(int n);
}  // namespace internal

}  // namespace u3mscan::reconstruction
