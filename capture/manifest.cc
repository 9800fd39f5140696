#include "capture/manifest.h"

namespace u3mscan {

const char* FrameRoleName(FrameRole role) {
  switch (role) {
    case FrameRole::kSample: return "sample";
    case FrameRole::kAmbient: return "ambient";
    case FrameRole::kDark: return "dark";
    case FrameRole::kFlat: return "flat";
    case FrameRole::kBoard: return "board";
    case FrameRole::kSphere: return "sphere";
    case FrameRole::kChart: return "chart";
    case FrameRole::kBacklight: return "backlight";
  }
  return "unknown";
}

const CameraSpec* Manifest::FindCamera(const std::string& id) const {
  for (const auto& camera : cameras) {
    if (camera.id == id) return &camera;
  }
  return nullptr;
}

const LightSpec* Manifest::FindLight(const std::string& id) const {
  for (const auto& light : lights) {
    if (light.id == id) return &light;
  }
  return nullptr;
}

}  // namespace u3mscan
