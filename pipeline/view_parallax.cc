#include "pipeline/view_parallax.h"

#include "pipeline/relief_registration.h"

namespace u3mscan {

void SetViewParallax(const Stack& views, const CalibrationResult& calibration, bool rectified_on_relief,
                     StageOptions* options) {
  reconstruction::ViewParallax parallax;
  const int chosen = options->photometric_stereo.view >= 0 ? options->photometric_stereo.view : MostVerticalView(views);
  if (chosen >= 0 && static_cast<std::size_t>(chosen) < views.views.size()) {
    const Eigen::Vector3d& camera = views.views[static_cast<std::size_t>(chosen)].centre_in_world_mm;
    parallax.camera_x_mm = camera.x();
    parallax.camera_y_mm = camera.y();
    parallax.camera_z_mm = camera.z();
    parallax.x0_mm = calibration.grid.x0_mm;
    parallax.y1_mm = calibration.grid.y1_mm;
    parallax.plane_z_mm = calibration.surface_z_mm;
    // A camera at or below the plane sees no height field: no parallax to take out.
    parallax.enabled = camera.z() > calibration.surface_z_mm;
  }
  options->placement_parallax = parallax;
  if (rectified_on_relief) parallax.enabled = false;
  options->integration.parallax = parallax;
  options->photometric_stereo.integration.parallax = parallax;
}

}  // namespace u3mscan
