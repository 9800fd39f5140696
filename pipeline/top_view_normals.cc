#include "pipeline/top_view_normals.h"

#include <algorithm>
#include <cstdio>
#include <map>
#include <stdexcept>
#include <utility>

#include "core/elapsed.h"
#include "pipeline/fine_grid.h"
#include "pipeline/plan_placement.h"

namespace u3mscan {

bool RefinesTopViewNormals(const StageOptions& options, int k) {
  return k > 1 && options.refine_top_view_normals && options.photometric_stereo.view >= 0;
}

fitting::ClusterModel ModelForTopViewNormals(const fitting::ClusterModel& model, const Stack& fitted, const Stack& top) {
  if (model.observation_levels.size() != fitted.observations.size()) {
    throw std::invalid_argument("ModelForTopViewNormals: the model's noise levels are not the fitted stack's observations");
  }
  std::map<std::pair<std::string, std::string>, double> level_of;  // (light id, camera id) -> level
  for (std::size_t i = 0; i < fitted.observations.size(); ++i) {
    const Observation& o = fitted.observations[i];
    level_of[{fitted.lights.at(static_cast<std::size_t>(o.light)).id,
              fitted.views.at(static_cast<std::size_t>(o.view)).camera_id}] = model.observation_levels[i];
  }
  fitting::ClusterModel out = model;
  out.options.refine_pixel_normals = true;
  // The pass keeps the normals alone, which are refined at the cluster's parameters either way:
  // no pixel's own parameters are fitted (FitMode::kPerPixel's step), only its closed-form colour.
  out.options.mode = fitting::FitMode::kClusters;
  out.observation_levels.clear();
  for (const Observation& o : top.observations) {
    const std::string& light = top.lights.at(static_cast<std::size_t>(o.light)).id;
    const std::string& camera = top.views.at(static_cast<std::size_t>(o.view)).camera_id;
    const auto found = level_of.find({light, camera});
    if (found == level_of.end()) {
      throw std::invalid_argument("ModelForTopViewNormals: light " + light + " of camera " + camera +
                                  " was not among the fitted observations");
    }
    out.observation_levels.push_back(found->second);
  }
  return out;
}

std::string TopViewNormalsDetail(int k, const std::string& camera_id, double seconds) {
  char detail[200];
  std::snprintf(detail, sizeof detail, "; normals refined on the %dx finer grid against view %s alone (%.2f s of it)", k,
                camera_id.c_str(), seconds);
  return detail;
}

fitting::FitResult FitSideRefiningTopViewNormals(const Stack& stack, const SideReconstruction& geometry,
                                                 FineReconstruction fine, const StageOptions& options,
                                                 RunReport* report, const ProgressCallback& progress,
                                                 Image* fine_height_mm) {
  if (fine_height_mm) *fine_height_mm = Image();
  if (fine.k <= 1 || fine.stack.observations.empty()) {
    throw std::logic_error("FitSideRefiningTopViewNormals: no fine stack of the top view");
  }
  ReportObliqueView(stack, report);
  const double start = SteadySeconds();
  const int k = fine.k;
  fitting::ClusterModel model;
  std::string detail;
  fitting::FitResult fit = FitSideKeepingModel(stack, geometry, options, progress, &model, &detail);

  const double fine_start = SteadySeconds();
  std::string placed;  // what the plan placement moved, for the report
  const std::string camera = fine.stack.views.at(static_cast<std::size_t>(fine.stack.observations.front().view)).camera_id;
  {
    const fitting::ClusterModel top = ModelForTopViewNormals(model, stack, fine.stack);
    const fitting::SurfaceGeometry fine_surface = FitGeometry(
        fine.side.photometric_stereo.normal, fine.side.photometric_stereo.albedo, fine.side.height_mm, options);
    fitting::FitResult fine_fit = fitting::StartPixelMaps(top, fine.stack.grid);
    fitting::PixelTally fine_tally;  // the maps' grid's tally is the one reported
    fitting::FitPixelRows(top, fine.stack, fine_surface, 0, &fine_fit, &fine_tally, progress);
    // Weighted as ReconstructSideSupersampled averaged photometric stereo's normals (a tilted
    // capture's integration has no parallax, so no weights), and placed on the plan along the top
    // camera's rays, which that average is not for a tilted capture (StageOptions::placement_parallax).
    const Image weights = SurfaceAreaWeights(fine_fit.normals, options.integration.parallax);
    const PlanPlacement placement = options.place_fine_pixels_on_plan
                                        ? PlanPlacement(fine.side.height_mm, fine.side.valid, options.placement_parallax, k)
                                        : PlanPlacement();
    placed = PlacementDetail(placement, fine.stack.grid.pitch_mm);
    if (fine_height_mm) {
      *fine_height_mm = IntegrateFineRefinedNormals(std::move(fine_fit.normals), fine.side.valid, weights, geometry.valid,
                                                    k, stack.grid.pitch_mm, HasPointLights(stack), options, progress,
                                                    placement, &fit.normals, &geometry.height_mm);
    } else {
      fit.normals = AverageNormalsOntoMaps(fine_fit.normals, k, stack.grid.pitch_mm, weights, placement);
    }
  }
  const double fine_seconds = SteadySeconds() - fine_start;
  fine = FineReconstruction();
  fit.times.total_s = SteadySeconds() - start;
  ReportFitStep(fit, detail + TopViewNormalsDetail(k, camera, fine_seconds) + placed, SteadySeconds() - start, report);
  return fit;
}

}  // namespace u3mscan
