#pragma once
// The integration's view parallax (reconstruction/normal_integration.h ViewParallax) from the
// capture: the camera whose normals are integrated and the plane its frames were rectified onto.

#include "capture/calibrate.h"
#include "core/stack.h"
#include "pipeline/presets.h"

namespace u3mscan {

// Sets options->integration.parallax, options->photometric_stereo.integration.parallax and
// options->placement_parallax for a side whose views are `views` (SideViews): the camera
// photometric stereo reads (options->photometric_stereo.view, else the most vertical view), on
// calibration.grid at calibration.surface_z_mm. All off when there is no view. The two
// integrations' are off when the frames are rectified on the relief (a tilted view: the grid point
// is then the surface point, no parallax left); the placement's stays on, since a finer grid
// (--ps-supersample) reads that view on the face's plane and the top view's refined normals are
// placed on the plan along its rays. Taking the integrations' (and with it the surface-area
// weights') on there too put a dome into a wide velvet capture's heights (17.6 -> 38.6 % of the
// range; docs/reconstruction.md, "A tilted capture's finer grid on the plan").
void SetViewParallax(const Stack& views, const CalibrationResult& calibration, bool rectified_on_relief,
                     StageOptions* options);

}  // namespace u3mscan
