#pragma once
// Cast shadows from the reconstructed geometry: an observation whose surface point cannot see its
// light past the height field is marked kCastShadow (core/stack.h), so that photometric stereo and
// the fitter leave it out instead of explaining a shadow with a tilted normal or a dark colour.
//
// How (docs/reconstruction.md, "Cast shadows"): for each pixel and light, a ray leaves the surface
// point (the pixel centre at its integrated height) toward the light (a directional light: its
// fixed direction; a point light: the straight line to its position) and marches over the height
// field in steps of step_px grid pixels along the sample plane, the height looked up bilinearly.
// The observation is marked when the ray passes below the height field by more than a bias (the
// height the ray climbs over bias_px pixels); the march stops when the ray rises above the map's highest point, leaves the map, or
// (point light) reaches the light. A light below the sample plane (direction z <= 0) shadows
// every pixel, as it lights nothing.
//
// Frames and units: world frame of the capture contract, heights in mm (larger = toward the
// camera), grids as core/stack.h MetricGrid.

#include "core/image.h"
#include "core/progress.h"
#include "core/stack.h"
#include "reconstruction/photometric_stereo.h"

namespace u3mscan::reconstruction {

struct CastShadowOptions {
  // March step along the sample plane, in pixels of the height map's grid. 0.5 samples every
  // bilinear cell at least twice: a ridge one pixel wide cannot be stepped over.
  double step_px = 0.5;
  // The ray must pass below the height field by the height it climbs over bias_px pixels along the
  // sample plane (bias_px * pitch_mm * tan(elevation of the ray), mm) to count as blocked: every
  // shadow is shortened by bias_px pixels, whatever the light's elevation. Absorbs the bilinear
  // surface's curvature at the start facet, which would otherwise shadow a facet by itself. (A
  // fixed height instead, 0.1 pitch, shortened a 5 deg light's shadows by 1.1 px and missed 10 % of
  // the grazing rig's shadowed observations on the true heights; test CastShadowChain.)
  double bias_px = 0.1;
  // Partial shadows. An observation is an average over its pixel's footprint (and the
  // rectification's resampling kernel, which reaches one pixel past the centre), so a shadow over
  // part of the footprint darkens it too, a tens-of-sigma outlier for the fit. With footprint_px
  // > 0 the observation is also marked when the ray from any of the 4 points footprint_px / 2
  // pixels of the height map's grid from the pixel centre, along the grid's axes (each at its own
  // height), is blocked: 1 covers the pixel, 2 the bilinear kernel's reach. 0: the centre only.
  double footprint_px = 0.0;
  // The heights the march runs over are the integrated ones times relief_scale (about any
  // reference: the test is the same). Integrated heights are shallower than the relief that casts
  // the shadows (photometric stereo flattens each pixel's mix of facets), so shadows come out
  // short; > 1 lengthens them. 1: the heights as integrated.
  double relief_scale = 1.0;

  bool Check() const;
};

struct CastShadowCounts {
  long long marked = 0;     // (pixel, observation) pairs set kCastShadow
  long long examined = 0;   // (pixel, observation) pairs looked at: pixels x observations
  double share() const { return examined > 0 ? static_cast<double>(marked) / static_cast<double>(examined) : 0.0; }
};

// Marks the cast shadows of every observation of `stack` over `height_mm` (1 channel, mm) lying on
// `height_grid`, a grid of the same world frame that contains the stack's grid: the stack's own
// grid, or the whole grid of which the stack is a band (rows offset by the band's first row) or
// a sample (pitch k p). Pixels of the stack outside the height map are not marked. kCastShadow is
// owned by this function: it is cleared on every observation first, then set anew (the other flags
// are kept); empty flag vectors are allocated (one byte per pixel) first. Shadows depend on the
// light only, so observations of several views of one light get the same marks.
// Throws std::invalid_argument when the height map does not match height_grid, options fail
// Check() or an observation's light index is out of range.
CastShadowCounts MarkCastShadows(const Image& height_mm, const MetricGrid& height_grid, Stack* stack,
                                 const CastShadowOptions& options = {});
// The height map on the stack's own grid.
CastShadowCounts MarkCastShadows(const Image& height_mm, Stack* stack, const CastShadowOptions& options = {});

struct ShadowMarkingSummary {
  CastShadowCounts counts;   // the marks the returned result was solved with
  double mark_seconds = 0;   // wall time of the marking and of the integration it needed (distant lights)
  // Share of the pixels solved again after the marks (distant lights: those with a mark or solved
  // from their neighbours; 0 when nothing was marked; 1 with point lights); -1 for near-light rounds.
  double solved_again_share = -1.0;
};

// Photometric stereo that leaves cast shadows out (sets kCastShadow on `stack`):
//   distant lights (or refine_height off): solve, integrate the normals (options.integration,
//     confidence as weights), mark, solve again (not when nothing was marked);
//   near point lights: RunPhotometricStereo's height refinement, with the marks renewed after each
//     integration (each round solves with the shadows of the height it solves at).
// The diffuse roughness is chosen on the first solve and kept. `summary` (optional) receives the
// final marks' counts and the marking time.
PhotometricStereoResult RunPhotometricStereoMarkingShadows(Stack* stack, const PhotometricStereoOptions& options,
                                                           const CastShadowOptions& shadow_options,
                                                           ShadowMarkingSummary* summary = nullptr,
                                                           const ProgressCallback& progress = {});

}  // namespace u3mscan::reconstruction
