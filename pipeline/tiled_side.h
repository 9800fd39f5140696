#pragma once
// One side of a capture processed band by band (pipeline/tiles.h), for scans whose whole Stack does
// not fit the memory budget. The same stages as the untiled path (stages.h), in sweeps over the
// bands; each sweep builds the band Stacks again from the frames (only the camera rows a band
// needs are read) and drops them:
//   sweep 1    photometric stereo at the anchor plane, band by band, into full-size maps; the fit's
//              sample (every k-th row and column, a grid of pitch k p) is copied out on the way and
//              the side's checks (frames without signal, usable pixels) run on it
//   sweeps 2.. near point lights: the whole normal map is integrated once per round and every band
//              solved again at the new heights (RunPhotometricStereo's refinement, round by round)
//   marks      distant lights: cast shadows marked from the integrated heights, and one sweep solves
//              again only the pixels a mark changes (SolvePhotometricStereoAgain, from sweep 1's
//              solve kept whole, as one band does); with a finer grid the fit then takes its fine
//              normals and albedo instead of solving the fine bands once more
//   integration of the whole normal map (as ReconstructSide)
//   relief     a tilted view only (relief_registration.h): the bands from here on are built at the
//              heights (top on the face) and their hidden pixels marked; one sweep solves
//              photometric stereo on them again and gathers the fit's sample anew; integration again
//   fit        clusters on the sample (fitting/tiled_fit.h FitClusterModel), then one sweep of the
//              per-pixel step with the clusters fixed (FitPixelRows), then the map decisions
//   residual   one sweep over the residual map's few observations, after the decisions
//   held out   with --hold-out-lights, those lights' frames are left out of every sweep above and
//              compared with the finished material in one last sweep (held_out_lights.h)
// Photometric stereo is per pixel, so a band's normals equal the untiled ones except for pixels
// regularised toward their neighbours near a band edge; the fit differs by its clusters (fitted on
// the sample instead of the whole grid). tests/pipeline/tiled_process_test.cc measures both.

#include <optional>
#include <string>
#include <vector>

#include "core/progress.h"
#include "fitting/principled_fit.h"
#include "pipeline/held_out_lights.h"
#include "pipeline/presets.h"
#include "pipeline/run_report.h"
#include "pipeline/stages.h"
#include "pipeline/tiles.h"

namespace u3mscan {

struct TiledSide {
  SideReconstruction reconstruction;  // full-size maps
  fitting::FitResult fit;             // full-size maps
  Image residual;                     // FitResidualMap over the whole grid
  double residual_mean = 0.0;
  bool fitted_normals = false;        // reconstruction's normals are the fit's (AdoptFittedNormals)
  Stack sample;                       // the fit's sample of the side's stack (thumbnails)
  std::optional<HeldOutCheck> held_out;  // with hold_out_lights: the material against their photographs
};

// hold_out_lights: light ids kept out of every stage and checked at the end (empty: none). Throws
// InputError as BuildSideStack does, and as TakeHeldOutFrames does for the held-out ids.
TiledSide ProcessSideTiled(const PreparedCapture& prepared, const std::string& side, const StageOptions& options,
                           const TilePlan& plan, const Image& alpha, int residual_observations,
                           const std::vector<std::string>& hold_out_lights, RunReport* report,
                           const ProgressCallback& progress = {});

}  // namespace u3mscan
