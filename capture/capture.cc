#include "capture/capture.h"

#include <algorithm>
#include <stdexcept>

#include "core/parallel.h"

namespace u3mscan {

namespace fs = std::filesystem;

Capture Capture::Open(const fs::path& folder_or_manifest, const CaptureOptions& options) {
  Capture capture;
  std::error_code ec;
  capture.folder_ = fs::is_directory(folder_or_manifest, ec) ? folder_or_manifest : folder_or_manifest.parent_path();
  std::vector<FrameHeader> headers;
  capture.manifest_ = std::make_shared<const Manifest>(ReadManifest(folder_or_manifest, &headers));
  capture.options_ = options;
  // ReadManifest has read every frame's header to check its size; keep what it says of reading.
  for (const FrameHeader& h : headers) capture.keeps_whole_.push_back(h.keep_whole);
  return capture;
}

const FrameSpec& Capture::frame(std::size_t index) const {
  if (index >= manifest_->frames.size()) {
    throw std::out_of_range("Capture: frame " + std::to_string(index) + " of " +
                            std::to_string(manifest_->frames.size()));
  }
  return manifest_->frames[index];
}

fs::path Capture::FramePath(std::size_t index) const { return folder_ / frame(index).file; }

const CameraSpec& Capture::FrameCamera(std::size_t index) const {
  return *manifest_->FindCamera(frame(index).camera);  // resolved by ReadManifest
}

const LightSpec* Capture::FrameLight(std::size_t index) const {
  const FrameSpec& f = frame(index);
  return f.light ? manifest_->FindLight(*f.light) : nullptr;
}

FrameDecodeOptions Capture::DecodeOptions(std::size_t index) const {
  const CameraSpec& camera = FrameCamera(index);
  FrameDecodeOptions options;
  options.response = camera.response;
  options.white_balance = camera.white_balance;
  return options;
}

std::vector<std::size_t> Capture::Frames(const FrameFilter& filter) const {
  std::vector<std::size_t> out;
  for (std::size_t i = 0; i < manifest_->frames.size(); ++i) {
    const FrameSpec& f = manifest_->frames[i];
    if (filter.role && f.role != *filter.role) continue;
    if (filter.camera && f.camera != *filter.camera) continue;
    if (filter.side && f.side != *filter.side) continue;
    if (filter.light && f.light != filter.light) continue;
    if (filter.lights_off && f.light) continue;
    out.push_back(i);
  }
  return out;
}

std::vector<std::size_t> Capture::FramesWithRole(FrameRole role) const {
  FrameFilter filter;
  filter.role = role;
  return Frames(filter);
}

std::vector<std::size_t> Capture::FramesOfCamera(const std::string& camera_id) const {
  FrameFilter filter;
  filter.camera = camera_id;
  return Frames(filter);
}

std::vector<std::size_t> Capture::FramesOfLight(const std::string& light_id) const {
  FrameFilter filter;
  filter.light = light_id;
  return Frames(filter);
}

std::vector<std::size_t> Capture::FramesOnSide(const std::string& side) const {
  FrameFilter filter;
  filter.side = side;
  return Frames(filter);
}

void Capture::Normalise(std::size_t index, const FrameLoadOptions& options, DecodedFrame* decoded) const {
  const FrameSpec& f = frame(index);
  double scale[3] = {1.0, 1.0, 1.0};
  if (options.divide_by_exposure) {
    for (double& s : scale) s /= f.exposure_s;
  }
  if (options.divide_by_intensity) {
    if (const LightSpec* light = FrameLight(index)) {
      for (int k = 0; k < 3; ++k) scale[k] /= light->intensity_rgb[k];
    }
  }
  if (scale[0] == 1.0 && scale[1] == 1.0 && scale[2] == 1.0) return;
  Image& rgb = decoded->rgb;
  for (int k = 0; k < 3; ++k) {
    auto plane = rgb.plane(k);
    const float s = static_cast<float>(scale[k]);
    ParallelFor(static_cast<std::size_t>(rgb.height()), [&](std::size_t b, std::size_t e) {
      const std::size_t w = static_cast<std::size_t>(rgb.width());
      for (std::size_t i = b * w; i < e * w; ++i) plane[i] *= s;
    });
  }
}

bool Capture::KeepsWhole(std::size_t index) const {
  frame(index);  // range check
  return keeps_whole_[index];
}

std::shared_ptr<const CompactFrame> Capture::CachedWhole(std::size_t index) const {
  {
    std::lock_guard<std::mutex> lock(cache_->mutex);
    for (const auto& entry : cache_->entries) {
      if (entry.first == index) return entry.second;
    }
    if (std::find(cache_->refused.begin(), cache_->refused.end(), index) != cache_->refused.end()) return nullptr;
  }
  if (options_.decode_cache_bytes == 0) return nullptr;
  // Decode outside the lock: other threads keep reading. Two threads asking for the same frame
  // at once may both decode it; the second insert is dropped.
  auto decoded = std::make_shared<const CompactFrame>(DecodeWholeFrame(FramePath(index), DecodeOptions(index)));
  std::lock_guard<std::mutex> lock(cache_->mutex);
  for (const auto& entry : cache_->entries) {
    if (entry.first == index) return entry.second;
  }
  // Full: keep the frames already cached and hand this one out uncached. The band sweeps read the
  // frames in the same order every time, so evicting (least recently used) would miss on every
  // read once the frames outnumber the cache; keeping them hits on the cached ones each sweep. The
  // frame is read by region from then on: decoding it whole again for every band would cost a
  // whole decode per band where a compressed TIFF inflates only the band's strips.
  if (cache_->bytes + decoded->bytes() > options_.decode_cache_bytes) {
    if (std::find(cache_->refused.begin(), cache_->refused.end(), index) == cache_->refused.end()) {
      cache_->refused.push_back(index);
    }
    return decoded;
  }
  cache_->entries.emplace_front(index, decoded);
  cache_->bytes += decoded->bytes();
  return decoded;
}

DecodedFrame Capture::LoadFrame(std::size_t index, const FrameLoadOptions& options) const {
  const fs::path path = FramePath(index);
  DecodedFrame decoded;
  std::shared_ptr<const CompactFrame> cached;
  {
    std::lock_guard<std::mutex> lock(cache_->mutex);
    for (const auto& entry : cache_->entries) {
      if (entry.first == index) cached = entry.second;
    }
  }
  decoded = cached ? cached->Crop(0, 0, cached->width, cached->height) : DecodeFrame(path, DecodeOptions(index));
  Normalise(index, options, &decoded);
  return decoded;
}

DecodedFrame Capture::LoadFrameRegion(std::size_t index, int x, int y, int w, int h,
                                      const FrameLoadOptions& options) const {
  const fs::path path = FramePath(index);
  DecodedFrame decoded;
  const std::shared_ptr<const CompactFrame> whole = KeepsWhole(index) ? CachedWhole(index) : nullptr;
  if (whole) {
    decoded = whole->Crop(x, y, w, h);
  } else {
    decoded = DecodeFrameRegion(path, DecodeOptions(index), x, y, w, h);
  }
  Normalise(index, options, &decoded);
  return decoded;
}

std::size_t Capture::cached_bytes() const {
  std::lock_guard<std::mutex> lock(cache_->mutex);
  return cache_->bytes;
}

std::size_t Capture::frames_read_by_region() const {
  std::lock_guard<std::mutex> lock(cache_->mutex);
  return cache_->refused.size();
}

void Capture::ReleaseCache() const {
  std::lock_guard<std::mutex> lock(cache_->mutex);
  cache_->entries.clear();
  cache_->bytes = 0;
  cache_->refused.clear();
}

}  // namespace u3mscan
