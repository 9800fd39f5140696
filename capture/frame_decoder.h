#pragma once
// Frame decoding: one image file of a capture folder -> linear float RGB plus a saturation mask.
// The rules (docs/capture-reading.md):
//   RAW (libraw; any camera it reads, DNG included): AHD demosaic, camera white balance (or the
//     manifest's), black level subtracted, 1.0 = the white level, no gamma, no auto-brightening,
//     sensor orientation (the file's rotation flag is ignored so pixels match the intrinsics).
//   16-bit TIFF/PNG and half/float EXR/TIFF (OpenImageIO): linear as stored.
//   8-bit JPEG/PNG/TIFF: sRGB, linearised.
//   A manifest `response {black_level, white_level}` maps linear data: (v - black) / (white - black).
// Bad files (not an image, truncated, absurd dimensions) throw InputError naming the file.

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <vector>

#include "capture/manifest.h"
#include "core/image.h"

namespace u3mscan {

enum class FrameEncoding {
  kRaw,     // decoded by libraw
  kLinear,  // 16-bit integer or float data, taken as linear
  kSrgb,    // 8-bit data, sRGB transfer curve removed
};

struct FrameHeader {
  int width = 0;   // pixels of the decoded frame
  int height = 0;
  FrameEncoding encoding = FrameEncoding::kLinear;
  // Region reads of this file cost a decode worth keeping, so Capture keeps the frame whole
  // (CompactFrame) for them: RAW (libraw decodes whole), PNG and JPEG (decoded from the top row
  // down to the region's last) and 8- or 16-bit scanline TIFF stored compressed (every band
  // sweep inflates its strips again). Not uncompressed or tiled TIFF, nor EXR or float files.
  bool keep_whole = false;
};

struct FrameDecodeOptions {
  // Manifest cameras[].response; levels in the file's code values (raw ADU, 0..65535, EXR values).
  std::optional<SensorResponse> response;
  // Manifest cameras[].white_balance: RAW multipliers [r, g, b]; absent = as shot.
  std::optional<std::array<double, 3>> white_balance;
};

// Linear RGB of one frame (or a region of it) and the pixels that must not be used as data.
struct DecodedFrame {
  Image rgb;                       // 3 channels, linear; 1.0 = white level (before normalisation)
  std::vector<std::uint8_t> saturated;  // width*height, row-major; 1 = at or above white level
  FrameEncoding encoding = FrameEncoding::kLinear;
  bool IsSaturated(int row, int col) const {
    return saturated[static_cast<std::size_t>(row) * rgb.width() + col] != 0;
  }
};

// Largest frame accepted, in pixels (a 2^31 x 2^31 header is a few bytes long).
inline constexpr std::int64_t kMaxFramePixels = std::int64_t{1} << 28;  // 268 megapixels
inline constexpr int kMaxFrameSide = 1 << 16;

// Which decoder a path goes to: .tif/.tiff/.png/.exr/.jpg/.jpeg -> OpenImageIO, anything else
// (.dng, .cr2, .nef, .arw, ...) -> libraw.
bool IsRawPath(const std::filesystem::path& path);

// Size, encoding and keep_whole from the header only (libraw's metadata parse / OIIO's open): no
// decoding.
FrameHeader ReadFrameHeader(const std::filesystem::path& path);

DecodedFrame DecodeFrame(const std::filesystem::path& path, const FrameDecodeOptions& options = {});

// A region [x, x+w) x [y, y+h) of a frame, equal to the same crop of DecodeFrame. OpenImageIO
// files read only the rows of the region (PNG and JPEG decode every row above it too); RAW files
// are decoded whole (use DecodeWholeFrame and CompactFrame::Crop to keep one decode for many
// regions, FrameHeader::keep_whole).
DecodedFrame DecodeFrameRegion(const std::filesystem::path& path, const FrameDecodeOptions& options, int x, int y,
                               int w, int h);

// A whole frame in 16 bits a channel, interleaved RGB, plus the mask: 7 bytes a pixel instead of
// 13 as float. RAW frames as libraw delivers them; 8- and 16-bit files as their codes with a
// table from code to linear value. What Capture caches for region reads of files whose header
// says keep_whole; a crop equals DecodeFrameRegion's read of the same region to the bit.
struct CompactFrame {
  int width = 0;
  int height = 0;
  FrameEncoding encoding = FrameEncoding::kRaw;
  std::vector<std::uint16_t> rgb16;     // interleaved R, G, B
  std::vector<std::uint8_t> saturated;  // width*height
  float scale = 1.0f;                   // linear value = rgb16 * scale, when linear_of_code is empty
  std::vector<float> linear_of_code;    // else linear value = linear_of_code[rgb16] (256 or 65536 entries)

  std::size_t bytes() const {
    return rgb16.size() * sizeof(std::uint16_t) + saturated.size() + linear_of_code.size() * sizeof(float);
  }
  // Throws std::out_of_range when the region is not inside the frame.
  DecodedFrame Crop(int x, int y, int w, int h) const;
};

// A RAW frame, or an 8- or 16-bit scanline file (TIFF, PNG, JPEG), decoded whole;
// std::invalid_argument for a float or tiled file, InputError for a bad file.
CompactFrame DecodeWholeFrame(const std::filesystem::path& path, const FrameDecodeOptions& options = {});

}  // namespace u3mscan
