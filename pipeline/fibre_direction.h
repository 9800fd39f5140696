#pragma once
// The fibres' direction per pixel, read from the relief: along a yarn, a cord or a float the
// surface normal barely changes; across it, it turns over the yarn's rounded cross-section. The
// structure tensor of the normal field (the sum over the normal's three components of the outer
// product of their gradients, averaged over a Gaussian window) has its largest eigenvector across
// the yarn; the fibres run along the other one. A lace's gimp cord turns all the way round a motif
// and a satin's floats change direction from weave to weave: one anisotropy rotation per cluster
// cannot follow them, a turn per pixel can (docs/fitting.md, "Fibre directions from the relief").
//
// The turn is given as the fitting's shading frame takes it (shading_frame.h): degrees about the
// pixel's normal from the unturned tangent (world +x projected into the tangent plane), in
// [0, 180), so that MakeShadingFrame(n, turn) has its tangent along the fibres' direction
// projected into the tangent plane.

#include "core/image.h"

namespace u3mscan {

struct FibreDirectionOptions {
  // Standard deviation of the Gaussian window the structure tensor is averaged over, in pixels of
  // the normal map. About a quarter of the narrowest yarn's width: the net threads of the synthetic
  // lace are 0.18 mm wide, 10 px at 1500 dpi.
  double window_px = 1.5;
  // Below this coherence ((l1 - l2) / (l1 + l2) of the tensor's eigenvalues, 0 for a field that
  // turns as much one way as the other, 1 for a perfect cylinder) the pixel has no fibre direction
  // and keeps the unturned tangent (turn 0).
  double min_coherence = 0.5;
  // Pixels whose tensor is below this trace (the sum of squared normal gradients per pixel^2: a
  // flat region) have no direction either.
  double min_trace = 1e-6;

  bool Check() const { return window_px > 0.0 && min_coherence >= 0.0 && min_coherence <= 1.0 && min_trace >= 0.0; }
};

// One channel, degrees in [0, 180) on the normal map's grid (pitch kept); 0 where no direction
// (coherence or trace too low, or the normal not a finite unit-like vector). `normals`: 3 channels,
// world frame (x right, y up; rows grow with -y). Throws std::invalid_argument for a map without 3
// channels or invalid options. Parallel over rows; 6 float planes of scratch (the tensor and its
// blurred copy).
Image FibreTurnFromNormals(const Image& normals, const FibreDirectionOptions& options = {});

// The turns of a grid k times finer averaged onto the maps' grid (pitch `maps_pitch_mm`): each map
// pixel the circular mean of its k x k fine turns as doubled angles (a stretch repeats every 180
// degrees), 0 where they cancel. A map pixel's observations mix its fine pixels', each fitted in its
// own frame, so this is the frame their cluster turn was fitted on top of; the maps' grid's own
// normals may not resolve the fibres at all (a satin's floats, 1.9 px wide at 300 dpi, read no
// coherent direction there). Throws std::invalid_argument for k < 1, a map that is not 1 channel or
// sides that are not multiples of k.
Image AverageTurnsOntoMaps(const Image& fine_turns, int k, double maps_pitch_mm);

}  // namespace u3mscan
