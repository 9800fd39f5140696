#pragma once
// A tilted capture's normals refined on the finer grid against its most vertical view alone.
//
// With a tilted view (relief_registration.h) photometric stereo reads the most vertical view alone,
// and the fit refines no normal against every view: the tilted view's observations bend them
// (UseTheMostVerticalViewForNormals). Photometric stereo's diffuse model reads a fabric's specular
// and sheen lobes as slope; once the clusters are fitted (with every view) those lobes are known,
// so each pixel of the finer grid (--ps-supersample) has its normal fitted once more against the
// top view's photographs with its nearest cluster's lobes (fitting/tiled_fit.h FitPixelRows, the
// per-pixel normal refinement on), and the map pixel's normal is their average as
// FitSideWithFineNormals makes it (docs/reconstruction.md, "Refining a tilted capture's normals
// against the top view"). The fine grid reads that view on the face's plane, so each fine pixel is
// placed on the plan along its camera's rays (StageOptions::placement_parallax; up to half a map
// pixel at a wide field's edges: docs/reconstruction.md, "A tilted capture's finer grid on the plan").
//
// The refined normals give the height its detail only: its wavelengths longer than a few map pixels
// stay photometric stereo's. The refined normals' own average, integrated, bent a 2048 px velvet
// into a bowl (height 3.26 -> 4.56 % of the range, docs/reconstruction.md).
//
// Only the normals are written from this pass: the parameter maps, the base colour and the fit's
// facets are the fit's on the maps' grid as before.

#include <string>

#include "core/image.h"
#include "core/progress.h"
#include "core/stack.h"
#include "fitting/principled_fit.h"
#include "fitting/tiled_fit.h"
#include "pipeline/presets.h"
#include "pipeline/run_report.h"
#include "pipeline/stages.h"
#include "pipeline/supersampled_reconstruction.h"

namespace u3mscan {

// True when a side's run refines its normals against the top view: a tilted view (its normals from
// one view, options.photometric_stereo.view >= 0), photometric stereo on a finer grid (k > 1) and
// options.refine_top_view_normals.
bool RefinesTopViewNormals(const StageOptions& options, int k);

// `model`, fitted on `fitted`'s observations, for the per-pixel step on `top`, whose observations are
// some of `fitted`'s (the same light id and camera; any order): each observation's noise level taken
// from the same (light, camera) of `fitted`, the per-pixel normal refinement on and the pixels' own
// parameters not fitted (FitMode::kClusters: the normals do not depend on them). Throws
// std::invalid_argument naming the light and camera of an observation `fitted` does not hold.
fitting::ClusterModel ModelForTopViewNormals(const fitting::ClusterModel& model, const Stack& fitted, const Stack& top);

// One band: the fit of FitSide (the clusters and the per-pixel step on the maps' grid, with the
// facets of `geometry`), then each pixel of `fine` (its stack: the top view's observations on the
// finer grid, ReconstructSideSupersampled's `keep_fine`) refined as above. `fit.normals` gets their
// average onto the maps (AverageNormalsOntoMaps, weighted as the reconstruction's and placed along
// options.placement_parallax by the fine photometric stereo's heights),
// `fine_height_mm` (not null) the height IntegrateFineRefinedNormals gives them with `geometry`'s
// height for the long wavelengths. Reports the fit step. `fine` is released before returning.
fitting::FitResult FitSideRefiningTopViewNormals(const Stack& stack, const SideReconstruction& geometry,
                                                 FineReconstruction fine, const StageOptions& options,
                                                 RunReport* report, const ProgressCallback& progress,
                                                 Image* fine_height_mm);

// The fit step's words for the pass: "; normals refined on the Kx finer grid against view CAMERA
// alone (S s of it)".
std::string TopViewNormalsDetail(int k, const std::string& camera_id, double seconds);

}  // namespace u3mscan
