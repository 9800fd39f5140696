#pragma once
// Dark and ambient subtraction (capture contract, frame roles `dark` and `ambient`).
//   dark:    the sensor with no light, per camera; the mean of a camera's dark frames is taken
//            away from every frame of that camera (taken as-is: darks are shot at the exposure
//            of the frames they correct, as the contract's scanners do).
//   ambient: the fabric with all lights off, per camera and side; after its own dark, divided by
//            its exposure (a rate per second) and taken away from every `sample` frame of that
//            camera and side, scaled by the sample's exposure.
// Differences are kept signed (noise around zero stays unbiased); later steps flag, not clamp.

#include <map>
#include <string>
#include <utility>
#include <vector>

#include "capture/calibration_frames.h"
#include "capture/manifest.h"
#include "core/image.h"

namespace u3mscan {

struct DarkAmbient {
  std::map<std::string, Image> dark_by_camera;                                 // frame units
  std::map<std::pair<std::string, std::string>, Image> ambient_rate_by_camera_side;  // per second
  std::vector<std::string> dark_frames;     // files used
  std::vector<std::string> ambient_frames;  // files used

  bool empty() const { return dark_by_camera.empty() && ambient_rate_by_camera_side.empty(); }
  // Takes dark (any role) and, for `sample` frames, ambient away from `frame` in place.
  void Apply(const FrameSpec& spec, Image& frame) const;
};

// Reads the manifest's dark and ambient frames through `load` and averages them. Throws
// InputError naming the frame when a dark or ambient frame has another size than the camera.
DarkAmbient BuildDarkAmbient(const Manifest& manifest, const FrameLoader& load);

}  // namespace u3mscan
