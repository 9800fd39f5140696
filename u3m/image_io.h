#pragma once
// Image files through OpenImageIO: the texture maps of a U3M and the truth maps of a synthetic
// capture. Colour maps are stored sRGB-encoded, data maps linear; in memory everything is linear
// float (core::Image).

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
  PixelEncoding encoding = PixelEncoding::kLinear;
  // Written into the file's resolution tags (0 = none). TIFF/PNG store it; EXR ignores it.
  double dpi = 0.0;
};

// Writes `image` (values clamped to 0..1 for integer formats) to `path`; the container comes from
// the extension (.png, .tif/.tiff, .exr). Atomic: writes a temporary file beside it, then renames.
// Throws InputError naming the file on failure.
void WriteImageFile(const Image& image, const std::filesystem::path& path, const ImageWriteOptions& options);

struct ImageReadInfo {
  int width = 0;
  int height = 0;
  int channels = 0;
  SampleFormat format = SampleFormat::kUInt8;
  bool srgb_tagged = false;  // the file says it holds sRGB-encoded values
};

// Reads the whole image as float. `encoding` says how to interpret integer values: kSrgb
// linearises them, kLinear takes them as they are. Float files are always taken as linear.
// Throws InputError naming the file when it cannot be read.
Image ReadImageFile(const std::filesystem::path& path, PixelEncoding encoding, ImageReadInfo* info = nullptr);

// Size and format from the header alone.
ImageReadInfo ReadImageInfo(const std::filesystem::path& path);

}  // namespace u3mscan
