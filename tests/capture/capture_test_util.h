#pragma once
// Shared helpers of the capture tests: a fresh temporary folder per test, small smooth images
// with known linear values, and a valid manifest to mutate.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>

#include "capture/manifest.h"
#include "core/image.h"

namespace u3mscan::testing {

// A folder under the system temp dir, unique per test, removed when the fixture ends.
class TempDir {
 public:
  TempDir() {
    static int counter = 0;  // several TempDirs in one test get different folders
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = std::filesystem::temp_directory_path() /
            ("u3mscan_capture_" + std::string(info->test_suite_name()) + "_" + info->name() + "_" +
             std::to_string(::getpid()) + "_" + std::to_string(counter++));
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

inline void WriteText(const std::filesystem::path& path, const std::string& text) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary);
  out << text;
}

// Smooth linear RGB in [lo, hi]: slow sinusoids of different phase per channel, so demosaicing
// error stays small and channels differ (a swapped channel shows).
inline Image SmoothRgb(int width, int height, float lo = 0.05f, float hi = 0.8f) {
  Image img(width, height, 3);
  for (int k = 0; k < 3; ++k) {
    for (int r = 0; r < height; ++r) {
      for (int c = 0; c < width; ++c) {
        const double t = 0.5 + 0.5 * std::sin(0.03 * c + 0.02 * r * (k + 1) + 2.1 * k);
        img.at(k, r, c) = static_cast<float>(lo + (hi - lo) * t);
      }
    }
  }
  return img;
}

// A valid manifest: one camera 64x64 with a pose, two directional lights, two sample frames,
// one dark frame; frames are .png paths under frames/ (files not written).
inline Manifest MakeManifest(int width = 64, int height = 64, const std::string& ext = ".png") {
  Manifest m;
  m.scanner = {"Acme", "LightDome 1", "SN-1", "acquire 2.0", nlohmann::json::object()};
  m.sample.name = "plain weave";
  m.sample.description = "test sample";
  CameraSpec cam;
  cam.id = "top";
  cam.width = width;
  cam.height = height;
  cam.intrinsics = {100.0, 100.0, (width - 1) / 2.0, (height - 1) / 2.0};
  CameraPose pose;
  pose.rotation = Eigen::Vector3d(1, -1, -1).asDiagonal();  // looking down -z
  pose.translation_mm = {0, 0, 500};
  cam.pose = pose;
  m.cameras.push_back(cam);
  for (int i = 0; i < 2; ++i) {
    LightSpec light;
    light.id = "L" + std::to_string(i);
    light.type = ManifestLightType::kDirectional;
    light.direction = Eigen::Vector3d(i == 0 ? 0.6 : -0.6, 0.0, 0.8);
    light.intensity_rgb = {1.0, 0.9 + 0.1 * i, 0.8};
    m.lights.push_back(light);
    FrameSpec f;
    f.file = "frames/sample_" + std::to_string(i) + ext;
    f.camera = "top";
    f.light = light.id;
    f.exposure_s = 0.01 * (i + 1);
    f.role = FrameRole::kSample;
    m.frames.push_back(f);
  }
  FrameSpec dark;
  dark.file = "frames/dark" + ext;
  dark.camera = "top";
  dark.exposure_s = 0.01;
  dark.role = FrameRole::kDark;
  m.frames.push_back(dark);
  return m;
}

}  // namespace u3mscan::testing
