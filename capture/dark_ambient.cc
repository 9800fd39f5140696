#include "capture/dark_ambient.h"

#include "core/error.h"
#include "core/logging.h"

namespace u3mscan {
namespace {

void Accumulate(Image& sum, const Image& frame, double weight) {
  auto& s = sum.data();
  const auto& f = frame.data();
  for (std::size_t i = 0; i < s.size(); ++i) s[i] += static_cast<float>(weight * f[i]);
}

void CheckSize(const Manifest& manifest, std::size_t index, const Image& frame) {
  const FrameSpec& spec = manifest.frames[index];
  const CameraSpec* camera = manifest.FindCamera(spec.camera);
  if (camera && (frame.width() != camera->width || frame.height() != camera->height || frame.channels() != 3)) {
    throw InputError(spec.file, "/frames/" + std::to_string(index),
                     "an RGB frame of the camera's size " + std::to_string(camera->width) + "x" +
                         std::to_string(camera->height) + ", got " + std::to_string(frame.width()) + "x" +
                         std::to_string(frame.height()));
  }
}

}  // namespace

void DarkAmbient::Apply(const FrameSpec& spec, Image& frame) const {
  if (const auto dark = dark_by_camera.find(spec.camera); dark != dark_by_camera.end() &&
                                                          dark->second.data().size() == frame.data().size()) {
    Accumulate(frame, dark->second, -1.0);
  }
  if (spec.role != FrameRole::kSample) return;
  if (const auto ambient = ambient_rate_by_camera_side.find({spec.camera, spec.side});
      ambient != ambient_rate_by_camera_side.end() && ambient->second.data().size() == frame.data().size()) {
    Accumulate(frame, ambient->second, -spec.exposure_s);
  }
}

DarkAmbient BuildDarkAmbient(const Manifest& manifest, const FrameLoader& load) {
  DarkAmbient result;
  std::map<std::string, int> dark_count;
  for (std::size_t i = 0; i < manifest.frames.size(); ++i) {
    const FrameSpec& spec = manifest.frames[i];
    if (spec.role != FrameRole::kDark) continue;
    DecodedFrame frame = load(i);
    CheckSize(manifest, i, frame.rgb);
    auto [it, inserted] = result.dark_by_camera.try_emplace(spec.camera, frame.rgb.width(), frame.rgb.height(), 3);
    Accumulate(it->second, frame.rgb, 1.0);
    ++dark_count[spec.camera];
    result.dark_frames.push_back(spec.file);
  }
  for (auto& [camera, sum] : result.dark_by_camera) {
    for (float& v : sum.data()) v /= static_cast<float>(dark_count[camera]);
  }
  std::map<std::pair<std::string, std::string>, int> ambient_count;
  for (std::size_t i = 0; i < manifest.frames.size(); ++i) {
    const FrameSpec& spec = manifest.frames[i];
    if (spec.role != FrameRole::kAmbient) continue;
    DecodedFrame frame = load(i);
    CheckSize(manifest, i, frame.rgb);
    result.Apply(spec, frame.rgb);  // its own dark (role ambient: no ambient of course)
    const auto key = std::make_pair(spec.camera, spec.side);
    auto [it, inserted] = result.ambient_rate_by_camera_side.try_emplace(key, frame.rgb.width(), frame.rgb.height(), 3);
    Accumulate(it->second, frame.rgb, 1.0 / spec.exposure_s);
    ++ambient_count[key];
    result.ambient_frames.push_back(spec.file);
  }
  for (auto& [key, sum] : result.ambient_rate_by_camera_side) {
    for (float& v : sum.data()) v /= static_cast<float>(ambient_count[key]);
  }
  LogInfo() << "dark/ambient: " << result.dark_frames.size() << " dark frame(s) for "
            << result.dark_by_camera.size() << " camera(s), " << result.ambient_frames.size()
            << " ambient frame(s) for " << result.ambient_rate_by_camera_side.size() << " camera/side pair(s)";
  return result;
}

}  // namespace u3mscan
