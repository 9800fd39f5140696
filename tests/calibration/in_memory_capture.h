#pragma once
// A capture held in memory for the calibration tests: a manifest whose frames are Images made by
// the test, and the FrameLoader that Calibrate/BuildStack read them through (no saturation).

#include <cstddef>
#include <map>
#include <utility>

#include "capture/calibrate.h"
#include "capture/manifest.h"
#include "core/image.h"

namespace u3mscan::testing {

struct InMemoryCapture {
  Manifest manifest;
  std::map<std::size_t, Image> frames;  // by index into manifest.frames

  // Appends the frame to the manifest with the image its loader returns.
  void Add(FrameSpec spec, Image image) {
    frames[manifest.frames.size()] = std::move(image);
    manifest.frames.push_back(std::move(spec));
  }
  // Valid while this object lives.
  FrameLoader Loader() const {
    return [this](std::size_t index) {
      DecodedFrame frame;
      frame.rgb = frames.at(index);
      frame.saturated.assign(frame.rgb.pixel_count(), 0);
      return frame;
    };
  }
};

}  // namespace u3mscan::testing
