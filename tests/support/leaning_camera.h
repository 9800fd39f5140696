#pragma once
// A camera whose rays lean over a small map, for the tests of averaging along the camera's rays
// (pipeline/fine_grid.h SurfaceAreaWeights, pipeline/plan_placement.h).

#include "reconstruction/normal_integration.h"

namespace u3mscan::testing {

// A camera 300 mm above the plane z = 0 (the sample's face) and 60 mm to the left of a map whose
// top-left corner is the origin: its rays lean by t = (camera - point).xy / 300, about (-0.2, 0)
// over the map.
inline reconstruction::ViewParallax CameraToTheLeft() {
  reconstruction::ViewParallax parallax;
  parallax.enabled = true;
  parallax.camera_x_mm = -60.0, parallax.camera_y_mm = 0.0, parallax.camera_z_mm = 300.0;
  parallax.x0_mm = 0.0, parallax.y1_mm = 0.0, parallax.plane_z_mm = 0.0;
  return parallax;
}

}  // namespace u3mscan::testing
