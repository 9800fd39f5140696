#include "capture/dark_ambient.h"

#include <gtest/gtest.h>

#include <map>

#include "core/error.h"

namespace u3mscan {
namespace {

constexpr float kTolerance = 1e-6f;

// Frames: two darks of camera "top" (0.02 and 0.04: mean 0.03), an ambient of 0.5 s reading
// 0.03 + 0.05 (rate 0.1 per second), a sample of 0.2 s and a flat of 0.2 s.
struct Frames {
  Manifest manifest;
  std::map<std::size_t, float> value;
  Frames() {
    CameraSpec camera;
    camera.id = "top";
    camera.width = 8;
    camera.height = 4;
    manifest.cameras.push_back(camera);
    Add({"d1.tif", "top", std::nullopt, "front", 0.2, FrameRole::kDark}, 0.02f);
    Add({"d2.tif", "top", std::nullopt, "front", 0.2, FrameRole::kDark}, 0.04f);
    Add({"amb.tif", "top", std::nullopt, "front", 0.5, FrameRole::kAmbient}, 0.08f);
  }
  void Add(FrameSpec spec, float v) {
    value[manifest.frames.size()] = v;
    manifest.frames.push_back(std::move(spec));
  }
  FrameLoader Loader(int width = 8) const {
    return [this, width](std::size_t i) {
      DecodedFrame frame;
      frame.rgb = Image(width, 4, 3, value.at(i));
      return frame;
    };
  }
};

TEST(DarkAmbient, DarkFromEveryFrameAmbientScaledFromSamplesOnly) {
  const Frames frames;
  const DarkAmbient model = BuildDarkAmbient(frames.manifest, frames.Loader());
  EXPECT_EQ(model.dark_frames.size(), 2u);
  EXPECT_EQ(model.ambient_frames.size(), 1u);
  Image sample(8, 4, 3, 0.5f);
  model.Apply({"s.tif", "top", std::string("L1"), "front", 0.2, FrameRole::kSample}, sample);
  // 0.5 - dark 0.03 - ambient rate 0.1/s * 0.2 s.
  EXPECT_NEAR(sample.at(1, 2, 3), 0.5f - 0.03f - 0.02f, kTolerance);
  Image flat(8, 4, 3, 0.5f);
  model.Apply({"f.tif", "top", std::string("L1"), "front", 0.2, FrameRole::kFlat}, flat);
  EXPECT_NEAR(flat.at(0, 0, 0), 0.5f - 0.03f, kTolerance);
  // Another side has no ambient frame: dark only.
  Image back(8, 4, 3, 0.5f);
  model.Apply({"b.tif", "top", std::string("L1"), "back", 0.2, FrameRole::kSample}, back);
  EXPECT_NEAR(back.at(2, 3, 7), 0.5f - 0.03f, kTolerance);
}

TEST(DarkAmbient, FrameOfTheWrongSizeNamesTheFrame) {
  const Frames frames;
  try {
    BuildDarkAmbient(frames.manifest, frames.Loader(6));
    FAIL() << "expected InputError";
  } catch (const InputError& error) {
    EXPECT_EQ(error.file(), "d1.tif");
    EXPECT_EQ(error.field(), "/frames/0");
  }
}

}  // namespace
}  // namespace u3mscan
