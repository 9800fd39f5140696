#pragma once
// What the calibration steps read: a decoded frame on its camera's pixel grid, and a loader that
// decodes frame i of the manifest when a step asks for it (frames are never all held at once).
//
// Values are linear, scaled so that the sensor's white level is 1, with the black level taken
// away, but NOT divided by exposure or light intensity and with no dark frame subtracted: those
// are calibration steps (dark_ambient.h, calibrate.h).

#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include "core/image.h"

namespace u3mscan {

struct LinearFrame {
  Image rgb;                              // 3 channels, camera pixels
  std::vector<std::uint8_t> saturated;    // width*height, 1 = at/above white level; empty = none
};

// Decodes Manifest::frames[frame_index]. Throws InputError for an unreadable file.
using FrameLoader = std::function<LinearFrame(std::size_t frame_index)>;

}  // namespace u3mscan
