#pragma once
// Capture: a checked capture folder (manifest + folder) with lazy frame access.
//
// Memory model (docs/capture-reading.md):
//   - Open() holds only the manifest: no pixel is read (frame headers are checked, not decoded).
//   - LoadFrame() decodes one whole frame and hands it to the caller (13 bytes a pixel as float
//     RGB + mask); Capture keeps nothing of it.
//   - LoadFrameRegion() returns a crop. Uncompressed or tiled TIFF and EXR files are read row band
//     by row band, only the rows of the region. RAW files can only be decoded whole, PNG and JPEG
//     files decode every row above the region too, and compressed TIFF strips are inflated again
//     on every sweep (FrameHeader::keep_whole, read once per frame), so such a frame is kept in a
//     cache in 16-bit form (CompactFrame, 7 bytes a pixel) and the band sweeps over all frames
//     decode each once.
//     The cache is bounded by CaptureOptions::decode_cache_bytes (when full it keeps the frames it
//     has: band sweeps read the frames in one order, where dropping the least recently used would
//     miss every time; a frame that found no room is read by region from then on, as a file
//     without keep_whole is) and can be emptied with ReleaseCache(). 32 frames of 36 MP: 8.1 GB of
//     cache for a one-decode sweep, against 15 GB as float.
// Thread safety: all const methods may be called from several threads at once. Copies of a
// Capture share one cache.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <list>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "capture/frame_decoder.h"
#include "capture/manifest.h"

namespace u3mscan {

struct CaptureOptions {
  // Upper bound of the cache of frames kept whole (FrameHeader::keep_whole: RAW, PNG, JPEG,
  // compressed TIFF) used by LoadFrameRegion, bytes. 0 disables the cache (each region read of
  // such a frame decodes the region alone, as a file without keep_whole is read).
  std::size_t decode_cache_bytes = std::size_t{9} << 30;  // 9 GiB: 32 frames of 36 MP
  bool Check() const { return true; }
};

struct FrameLoadOptions {
  bool divide_by_exposure = false;   // values / exposure_s: radiance per second of exposure
  bool divide_by_intensity = false;  // values / the light's intensity [r, g, b]; no-op for light null
};

// Which frames to list; unset members match every frame.
struct FrameFilter {
  std::optional<FrameRole> role;
  std::optional<std::string> camera;
  std::optional<std::string> side;
  std::optional<std::string> light;  // frames lit by this light id
  bool lights_off = false;           // only frames with light == null (dark, ambient, ...)
};

class Capture {
 public:
  // ReadManifest on the folder (or a capture.json path): throws InputError on any violation.
  static Capture Open(const std::filesystem::path& folder_or_manifest, const CaptureOptions& options = {});

  const Manifest& manifest() const { return *manifest_; }
  const std::filesystem::path& folder() const { return folder_; }
  std::size_t frame_count() const { return manifest_->frames.size(); }
  const FrameSpec& frame(std::size_t index) const;
  std::filesystem::path FramePath(std::size_t index) const;
  const CameraSpec& FrameCamera(std::size_t index) const;
  const LightSpec* FrameLight(std::size_t index) const;  // nullptr for lights-off frames
  // The decoder settings the manifest gives a frame (its camera's response and white balance).
  FrameDecodeOptions DecodeOptions(std::size_t index) const;

  // Frame indices in manifest order.
  std::vector<std::size_t> Frames(const FrameFilter& filter) const;
  std::vector<std::size_t> FramesWithRole(FrameRole role) const;
  std::vector<std::size_t> FramesOfCamera(const std::string& camera_id) const;
  std::vector<std::size_t> FramesOfLight(const std::string& light_id) const;
  std::vector<std::size_t> FramesOnSide(const std::string& side) const;

  // Whole frame, decoded now. Saturation flags are not changed by normalisation.
  DecodedFrame LoadFrame(std::size_t index, const FrameLoadOptions& options = {}) const;
  // [x, x+w) x [y, y+h) of the frame; equal to the same crop of LoadFrame. Throws
  // std::out_of_range when the region is not inside the frame.
  DecodedFrame LoadFrameRegion(std::size_t index, int x, int y, int w, int h, const FrameLoadOptions& options = {}) const;
  // Rows [y, y+rows) over the full width: the band API for streaming stages.
  DecodedFrame LoadFrameRows(std::size_t index, int y, int rows, const FrameLoadOptions& options = {}) const {
    return LoadFrameRegion(index, 0, y, FrameCamera(index).width, rows, options);
  }

  std::size_t cached_bytes() const;
  // Frames kept whole by their header that found no room in the cache: read by region since.
  std::size_t frames_read_by_region() const;
  void ReleaseCache() const;

 private:
  Capture() = default;
  void Normalise(std::size_t index, const FrameLoadOptions& options, DecodedFrame* frame) const;
  // The frame decoded whole, from the cache or decoded and cached now; null when the frame found no
  // room in the cache before (its region reads then decode the region alone).
  std::shared_ptr<const CompactFrame> CachedWhole(std::size_t index) const;
  // FrameHeader::keep_whole of the frame's file (read by Open).
  bool KeepsWhole(std::size_t index) const;

  std::shared_ptr<const Manifest> manifest_;
  std::vector<bool> keeps_whole_;  // per frame, in the manifest's order: FrameHeader::keep_whole (Open)
  std::filesystem::path folder_;
  CaptureOptions options_;

  struct Cache {
    std::mutex mutex;
    std::list<std::pair<std::size_t, std::shared_ptr<const CompactFrame>>> entries;  // latest first
    std::size_t bytes = 0;
    std::vector<std::size_t> refused;  // frames decoded whole once that found no room
  };
  std::shared_ptr<Cache> cache_ = std::make_shared<Cache>();
};

}  // namespace u3mscan
