#pragma once
// One side of a capture from its frames to its fitted maps, as `u3mscan process` runs it, so that
// `u3mscan fit` gives the same material as `process` on every capture: the alpha from the side's
// backlight frame; with a tilted view, its frames registered on the relief and the normals from
// the most vertical view (relief_registration.h); photometric stereo on a finer grid when the
// camera resolves it (--ps-supersample, supersampled_reconstruction.h), the fit then taking its
// facets; one band when the stack fits the memory budget, else bands of rows (tiled_side.h); the
// fitted normals adopted where the fit refines them; the report's residual map; the held-out
// lights' check.

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

struct SideRunOptions {
  // Memory budget of one band's stack, GiB (ProcessOptions::max_memory_gib).
  double max_memory_gib = 4.0;
  // Photometric stereo this many times finer than the maps: 0 = as fine as the top camera
  // resolves, 1 to kMaxPsSupersample (ProcessOptions::ps_supersample).
  int ps_supersample = 0;
  // Light ids left out of reconstruction and fit and compared with the material afterwards.
  std::vector<std::string> hold_out_lights;
};

struct SideRun {
  Image alpha;                        // from the backlight frame (empty: none, the sample is whole)
  TilePlan plan;                      // one band, or the bands the side was processed in
  int ps_supersample = 1;             // the finer grid's factor the run chose (1: the maps' grid)
  Stack stack;                        // the whole stack (one band) or the fit's sample (bands)
  SideReconstruction reconstruction;  // full-size maps
  fitting::FitResult fit;             // full-size maps
  bool fitted_normals = false;        // the reconstruction's normals are the fit's (AdoptFittedNormals)
  Image residual;                     // FitResidualMap over the whole grid (kResidualObservations)
  double residual_mean = 0.0;
  std::optional<HeldOutCheck> held_out;  // with hold_out_lights
};

// The capture's cache of frames kept decoded (RAW, PNG, JPEG, compressed TIFF) gets the same budget
// as one band's stack: --max-memory bounds both. Set before PrepareCapture, which opens the capture.
void SetDecodeCacheBudget(double max_memory_gib, StageOptions* stages);

// A side's stage options, decided from its cameras before any stack is built: with a tilted view
// the normals from the most vertical view (relief_registration.h), and the heights integrated along
// the camera's rays unless the frames are registered on the relief (view_parallax.h).
struct SideStages {
  Stack views;               // SideViews: the grid and the side's views, no observations
  bool tilted_view = false;  // NeedsReliefRegistration(views)
  StageOptions options;      // `stages` with the two settings above
};
SideStages StagesForSide(const PreparedCapture& prepared, const std::string& side, const StageOptions& stages);

// The side's alpha from its backlight frame (pipeline/alpha_map.h), rectified on the face's plane;
// empty when the capture has no backlight frame for the side or the frame shows no holes. Adds the
// step "alpha SIDE" to `report`.
Image SideAlpha(const PreparedCapture& prepared, const std::string& side, RunReport* report);

// Observations the render-residual map of the report averages over (spread over the stack).
inline constexpr int kResidualObservations = 6;

// `stages`: the preset's options with the command line's overrides; the tilted view's and the
// parallax's settings are made here from the side's cameras. Adds the side's steps to `report`
// and its plan to report->options ("ps_supersample_<side>"). Throws InputError as
// BuildSideStack and TakeHeldOutObservations do.
SideRun RunSide(const PreparedCapture& prepared, const std::string& side, const StageOptions& stages,
                const SideRunOptions& options, RunReport* report, const ProgressCallback& progress = {});

}  // namespace u3mscan
