#pragma once
// The integration's view parallax (reconstruction/normal_integration.h ViewParallax) from the
// capture: the camera whose normals are integrated and the plane its frames were rectified onto.

#include "capture/calibrate.h"
#include "core/stack.h"
#include "pipeline/presets.h"

namespace u3mscan {

// Sets options->integration.parallax and options->photometric_stereo.integration.parallax for a
// side whose views are `views` (SideViews): the camera photometric stereo reads
// (options->photometric_stereo.view, else the most vertical view), on calibration.grid at
// calibration.surface_z_mm. Leaves them off when the frames are rectified on the relief (a tilted
// view: the grid point is then the surface point, no parallax left) or when there is no view.
void SetViewParallax(const Stack& views, const CalibrationResult& calibration, bool rectified_on_relief,
                     StageOptions* options);

}  // namespace u3mscan
