#pragma once
// Image files through OpenImageIO: the texture maps of a U3M and the truth maps of a synthetic
// capture. Colour maps are stored sRGB-encoded and tagged sRGB, data maps linear with no colour
// profile; in memory everything is linear float (core::Image). u3m/texture_map.h adds the map kinds
// (colour, data, normal) and the U3M means on top of this file.

#include <cstdint>
#include <ctime>
#include <filesystem>
#include <string>

#include "core/image.h"

namespace u3mscan {

enum class PixelEncoding {
  kLinear,  // data maps (roughness, normal, displacement, ...) and float EXR: values as they are
  kSrgb,    // colour maps (basecolor): linear in memory, sRGB transfer curve in the file
};

enum class SampleFormat { kUInt8, kUInt16, kFloat32 };

struct ImageWriteOptions {
  SampleFormat format = SampleFormat::kUInt16;
  // kSrgb with an integer format: channels 0..2 get the sRGB curve (channel 3, alpha, stays linear)
  // and the file is tagged sRGB (PNG sRGB/gAMA/cHRM chunks, TIFF EXIF ColorSpace = 1). kLinear, and
  // every float file, carry no colour tag at all.
  PixelEncoding encoding = PixelEncoding::kLinear;
  // Pixels per inch written into the file's resolution tags (0 = none). PNG stores whole pixels
  // per metre (300 dpi reads back as 299.9994); TIFF stores it exactly; EXR ignores it.
  double dpi = 0.0;
  double dpi_y = 0.0;  // 0 = same as dpi
  // TIFF DateTime tag, written in UTC (0 = now). Fix it for reproducible files; PNG and EXR carry
  // no time.
  std::time_t modified_utc = 0;
};

// Writes `image` (values clamped to 0..1 for integer formats) to `path`; the container comes from
// the extension (.png, .tif/.tiff, .exr). Integer samples are EncodeSample() codes. Atomic: writes
// a temporary file beside it, then renames. Throws InputError naming the file on failure.
void WriteImageFile(const Image& image, const std::filesystem::path& path, const ImageWriteOptions& options);

struct ImageReadInfo {
  int width = 0;
  int height = 0;
  int channels = 0;
  SampleFormat format = SampleFormat::kUInt8;  // kFloat32 for every non-8/16-bit integer type
  bool srgb_tagged = false;  // the file says it holds sRGB-encoded values (not merely assumed)
  double dpi_x = 0.0;        // from the resolution tags, 0 when absent or unitless
  double dpi_y = 0.0;
};

// Reads the whole image as float. `encoding` says how to interpret integer values: kSrgb
// linearises channels 0..2 (DecodeSample), kLinear takes code / max as it is. Float files are
// always taken as linear. Throws InputError naming the file when it cannot be read.
Image ReadImageFile(const std::filesystem::path& path, PixelEncoding encoding, ImageReadInfo* info = nullptr);

// Size and format from the header alone.
ImageReadInfo ReadImageInfo(const std::filesystem::path& path);

// The quantiser every integer write uses: the value is clamped to 0..1 (NaN -> 0), sRGB-encoded
// for kSrgb, and rounded to the nearest of 0..255 (kUInt8) or 0..65535 (kUInt16).
// `format` must be an integer format.
std::uint32_t EncodeSample(float linear, PixelEncoding encoding, SampleFormat format);
// Inverse of EncodeSample as a reader applies it: code / max, sRGB-decoded for kSrgb.
float DecodeSample(std::uint32_t code, PixelEncoding encoding, SampleFormat format);

}  // namespace u3mscan
