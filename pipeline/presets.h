#pragma once
// Presets: one word that trades accuracy for run time across every stage (docs/presets.md gives
// what each changes and its measured cost).
//   fast      least-squares photometric stereo, DCT integration, few clusters, no per-pixel refit
//   balanced  robust photometric stereo (band + IRLS), DCT integration, default clustering, per-pixel refit
//   best      robust photometric stereo with more reweighting, edge-keeping robust integration, more
//             clusters and samples, longer per-pixel refit

#include <string>

#include "capture/calibrate.h"
#include "capture/capture.h"
#include "fitting/principled_fit.h"
#include "pipeline/fibre_direction.h"
#include "reconstruction/cast_shadows.h"
#include "reconstruction/normal_integration.h"
#include "reconstruction/photometric_stereo.h"

namespace u3mscan {

enum class Preset { kFast, kBalanced, kBest };

// "fast", "balanced", "best"; ParsePreset throws std::invalid_argument for another word.
std::string PresetName(Preset preset);
Preset ParsePreset(const std::string& name);

// Every stage's options, as one preset sets them.
struct StageOptions {
  CaptureOptions capture;  // the bound of the cache of frames kept whole (ProcessCapture: --max-memory)
  CalibrationOptions calibration;
  reconstruction::PhotometricStereoOptions photometric_stereo;
  reconstruction::IntegrationOptions integration;  // distant lights (near lights integrate inside PS)
  // Cast shadows marked from the reconstructed heights and left out of photometric stereo and the
  // fit (reconstruction/cast_shadows.h). On in every preset: marking costs one march per pixel and
  // light, plus (distant lights) one integration and one more solve.
  bool mark_cast_shadows = true;
  // Partial shadows too, the same in every preset: a footprint of 2 px (the resampling kernel's
  // reach) and the relief x 1.3 (what the integrated heights smooth away); measured on the six
  // fabric scenes (docs/reconstruction.md, "Cast shadows"). CastShadowOptions' own defaults mark
  // from the pixel centre on the heights as they are.
  reconstruction::CastShadowOptions cast_shadows{.footprint_px = 2.0, .relief_scale = 1.3};
  fitting::FitOptions fit;
  // With photometric stereo on a finer grid (--ps-supersample): the fit's clusters (gather,
  // k-means, Ceres fits, observability) on the fine stack (bands: a sample of it) and its normals,
  // where a pixel holds fewer yarn facets, instead of on the maps' (pipeline/supersampled_reconstruction.h).
  // Off only for comparisons (`process --fit-on-maps-grid`).
  bool fit_clusters_on_fine_grid = true;
  // With photometric stereo on a finer grid, and the fit's per-pixel step run there for the
  // normals (FitOptions::refine_pixel_normals): each map pixel's base colour is the mean of its
  // fitted fine pixels' (pipeline/fine_colour.h), not the maps' grid's fit, which takes the spread
  // of a map pixel's facet normals for a darker colour (crevices 4-6 L*). Off only for
  // comparisons (`process --fit-on-maps-grid`).
  bool base_colour_from_fine_grid = true;
  // With photometric stereo on a finer grid and the view's parallax on: the fine pixels' normals,
  // heights and base colour averaged onto the maps where their surface points lie in plan, found
  // from the fine heights (pipeline/plan_placement.h), not where their camera rays met the grid.
  // Off only for comparisons (`process --no-plan-placement`).
  bool place_fine_pixels_on_plan = true;
  // The camera rays along which the fit's refined fine normals are placed on the plan (set with
  // integration.parallax by pipeline/view_parallax.h): the integration's, or, for a capture with a
  // tilted view, whose heights are integrated without it, the most vertical view's on the face's
  // plane. Its finer grid reads that view there, so its fine pixels lie where those rays meet the
  // plane, up to half a map pixel from the plan at a wide field's edges (pipeline/top_view_normals.h).
  reconstruction::ViewParallax placement_parallax;
  // With a tilted view and photometric stereo on a finer grid: the fit models every observation as
  // the mixture of each map pixel's fine normals as its camera sees them (fitting/facet_mixture.h,
  // SideReconstruction::fine_normals), not with the pixel's one normal. Off only for comparisons
  // (`process --one-normal-per-pixel`).
  bool fit_facets = true;
  // With a tilted view and photometric stereo on a finer grid: once the clusters are fitted, each
  // fine pixel's normal is refined against the top view's photographs with its cluster's lobes and
  // the written normals are their average, the height taking its detail from them
  // (pipeline/top_view_normals.h). Off only for comparisons (`process --no-top-view-refinement`):
  // the normals are then photometric stereo's of the top view.
  bool refine_top_view_normals = true;
  // The fit's shading frame turned per pixel along the fibres that the normals' relief shows
  // (pipeline/fibre_direction.h, fitting::SurfaceGeometry::fibre_turn_deg), each cluster's
  // anisotropy rotation fitted on top (`process --follow-fibres`; in bands too, pipeline/tiled_side.cc).
  bool follow_fibres = false;
  FibreDirectionOptions fibre_directions;
  // In bands (pipeline/tiled_side.cc), sweeps reuse the solves of earlier sweeps instead of
  // repeating them: with distant lights the marked sweep solves again only the pixels a mark
  // changes (SolvePhotometricStereoAgain, from the first sweep's whole solve: 37 B a fine pixel
  // with a finer grid), and with a finer grid the fit's fine pass takes the last sweep's fine
  // normals and albedo (24 B a fine pixel) and cast-shadow marks (1 bit a fine pixel and light)
  // when that sweep is known before it runs. The same maps either way; off only for tests.
  bool reuse_band_solves = true;
};

StageOptions OptionsForPreset(Preset preset);

}  // namespace u3mscan
