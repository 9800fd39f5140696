#pragma once
// What the calibration steps read: decoded frames (capture/frame_decoder.h DecodedFrame: linear
// RGB, 1.0 = white level, black level taken away, NOT divided by exposure or light intensity, no
// dark frame subtracted) handed out one at a time by a loader, so frames are decoded when a step
// asks and never all held at once. Calibrate(const Capture&) uses Capture::LoadFrame; tests hand
// in frames made in memory.

#include <cstddef>
#include <functional>

#include "capture/frame_decoder.h"

namespace u3mscan {

// Decodes Manifest::frames[frame_index]. Throws InputError for an unreadable file.
using FrameLoader = std::function<DecodedFrame(std::size_t frame_index)>;

}  // namespace u3mscan
