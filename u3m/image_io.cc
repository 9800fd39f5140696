#include "u3m/image_io.h"

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <system_error>
#include <vector>

#include "core/colour.h"
#include "core/error.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;
namespace oiio = OIIO;

oiio::TypeDesc ToTypeDesc(SampleFormat format) {
  switch (format) {
    case SampleFormat::kUInt8: return oiio::TypeDesc::UINT8;
    case SampleFormat::kUInt16: return oiio::TypeDesc::UINT16;
    case SampleFormat::kFloat32: return oiio::TypeDesc::FLOAT;
  }
  return oiio::TypeDesc::FLOAT;
}

SampleFormat FromTypeDesc(const oiio::TypeDesc& type) {
  if (type == oiio::TypeDesc::UINT8) return SampleFormat::kUInt8;
  if (type == oiio::TypeDesc::UINT16) return SampleFormat::kUInt16;
  return SampleFormat::kFloat32;
}

ImageReadInfo InfoFromSpec(const oiio::ImageSpec& spec) {
  ImageReadInfo info;
  info.width = spec.width;
  info.height = spec.height;
  info.channels = spec.nchannels;
  info.format = FromTypeDesc(spec.format);
  const std::string colour_space = spec.get_string_attribute("oiio:ColorSpace");
  info.srgb_tagged = colour_space == "sRGB";
  return info;
}

}  // namespace

void WriteImageFile(const Image& image, const fs::path& path, const ImageWriteOptions& options) {
  const int w = image.width(), h = image.height(), c = image.channels();
  if (w <= 0 || h <= 0 || c <= 0) {
    throw InputError(path.string(), "", "an image with at least one pixel and channel to write");
  }
  // Interleave, encode and clamp in one pass; integer formats are quantised by OIIO with rounding.
  const bool integer = options.format != SampleFormat::kFloat32;
  std::vector<float> interleaved(image.pixel_count() * c);
  for (int ch = 0; ch < c; ++ch) {
    auto plane = image.plane(ch);
    for (std::size_t i = 0; i < plane.size(); ++i) {
      float v = plane[i];
      if (integer) {
        v = std::clamp(v, 0.0f, 1.0f);
        if (options.encoding == PixelEncoding::kSrgb) v = LinearToSrgb(v);
      }
      interleaved[i * c + ch] = v;
    }
  }

  oiio::ImageSpec spec(w, h, c, ToTypeDesc(options.format));
  if (options.encoding == PixelEncoding::kSrgb) {
    spec.attribute("oiio:ColorSpace", "sRGB");
  } else {
    spec.attribute("oiio:ColorSpace", "Linear");
  }
  if (options.dpi > 0.0) {
    spec.attribute("XResolution", static_cast<float>(options.dpi));
    spec.attribute("YResolution", static_cast<float>(options.dpi));
    spec.attribute("ResolutionUnit", "inch");
  }
  if (path.extension() == ".exr") spec.attribute("compression", "zip");

  // Temporary name keeps the extension so OIIO picks the right writer.
  fs::path temp = path;
  temp.replace_filename("." + path.stem().string() + ".partial" + path.extension().string());
  {
    auto out = oiio::ImageOutput::create(temp.string());
    if (!out) throw InputError(path.string(), "", "a writable image format (.png, .tif, .exr): " + oiio::geterror());
    if (!out->open(temp.string(), spec) ||
        !out->write_image(oiio::TypeDesc::FLOAT, interleaved.data()) || !out->close()) {
      const std::string error = out->geterror();
      std::error_code ignored;
      fs::remove(temp, ignored);
      throw InputError(path.string(), "", "a writable image file: " + error);
    }
  }
  std::error_code ec;
  fs::rename(temp, path, ec);
  if (ec) {
    fs::remove(temp, ec);
    throw InputError(path.string(), "", "a location that can be renamed into: " + ec.message());
  }
}

ImageReadInfo ReadImageInfo(const fs::path& path) {
  auto in = oiio::ImageInput::open(path.string());
  if (!in) throw InputError(path.string(), "", "a readable image (PNG, TIFF, EXR, JPEG): " + oiio::geterror());
  return InfoFromSpec(in->spec());
}

Image ReadImageFile(const fs::path& path, PixelEncoding encoding, ImageReadInfo* info_out) {
  auto in = oiio::ImageInput::open(path.string());
  if (!in) throw InputError(path.string(), "", "a readable image (PNG, TIFF, EXR, JPEG): " + oiio::geterror());
  const oiio::ImageSpec& spec = in->spec();
  const ImageReadInfo info = InfoFromSpec(spec);
  if (info_out) *info_out = info;
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0) {
    throw InputError(path.string(), "", "an image with a positive size");
  }
  // Refuse absurd headers before allocating (a 2^31 x 2^31 PNG header is a few bytes).
  constexpr std::size_t kMaxValues = std::size_t{1} << 32;
  const std::size_t values = static_cast<std::size_t>(spec.width) * spec.height * spec.nchannels;
  if (values > kMaxValues) {
    throw InputError(path.string(), "", "an image of at most 2^32 samples, header says " +
                                            std::to_string(spec.width) + "x" + std::to_string(spec.height) +
                                            "x" + std::to_string(spec.nchannels));
  }
  std::vector<float> interleaved(values);
  if (!in->read_image(0, 0, 0, spec.nchannels, oiio::TypeDesc::FLOAT, interleaved.data())) {
    throw InputError(path.string(), "", "complete image data: " + in->geterror());
  }
  in->close();

  const bool linearise = encoding == PixelEncoding::kSrgb && info.format != SampleFormat::kFloat32;
  Image image(spec.width, spec.height, spec.nchannels);
  const int c = spec.nchannels;
  for (int ch = 0; ch < c; ++ch) {
    auto plane = image.plane(ch);
    for (std::size_t i = 0; i < plane.size(); ++i) {
      const float v = interleaved[i * c + ch];
      // sRGB alpha channels stay linear: only colour channels carry the transfer curve.
      plane[i] = (linearise && ch < 3) ? SrgbToLinear(v) : v;
    }
  }
  return image;
}

}  // namespace u3mscan
