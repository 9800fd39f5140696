#include "u3m/image_io.h"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <ctime>
#include <fstream>
#include <random>
#include <stdexcept>
#include <system_error>
#include <vector>

#include "core/colour.h"
#include "core/error.h"
#include "core/parallel.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;
namespace oiio = OIIO;

std::uint32_t MaxCode(SampleFormat format) { return format == SampleFormat::kUInt8 ? 255u : 65535u; }

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

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// OIIO reports every untagged PNG as "sRGB" (the PNG default), so the tag is read from the chunks
// themselves: an sRGB chunk, or an embedded ICC profile named like sRGB (iCCP), before the image data.
bool PngHasSrgbTag(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  unsigned char signature[8];
  if (!in.read(reinterpret_cast<char*>(signature), 8)) return false;
  for (int chunk = 0; chunk < 1000; ++chunk) {
    unsigned char header[8];
    if (!in.read(reinterpret_cast<char*>(header), 8)) return false;
    const std::uint32_t length = (std::uint32_t{header[0]} << 24) | (std::uint32_t{header[1]} << 16) |
                                 (std::uint32_t{header[2]} << 8) | header[3];
    const std::string type(reinterpret_cast<char*>(header + 4), 4);
    if (type == "sRGB") return true;
    if (type == "IDAT" || type == "IEND") return false;
    if (type == "iCCP") {
      std::string name(std::min<std::uint32_t>(length, 80), '\0');
      if (!in.read(name.data(), static_cast<std::streamsize>(name.size()))) return false;
      name.resize(std::strlen(name.c_str()));
      return Lower(name).find("srgb") != std::string::npos;
    }
    in.seekg(static_cast<std::streamoff>(length) + 4, std::ios::cur);  // data + CRC
  }
  return false;
}

double DpiFrom(float resolution, const std::string& unit) {
  if (!(resolution > 0.0f) || !std::isfinite(resolution)) return 0.0;
  const std::string u = Lower(unit);
  if (u == "in" || u == "inch") return resolution;
  if (u == "cm") return resolution * 2.54;
  return 0.0;
}

ImageReadInfo InfoFromSpec(const oiio::ImageSpec& spec, const fs::path& path, bool png) {
  ImageReadInfo info;
  info.width = spec.width;
  info.height = spec.height;
  info.channels = spec.nchannels;
  info.format = FromTypeDesc(spec.format);
  if (png) {
    info.srgb_tagged = PngHasSrgbTag(path);
  } else {
    // TIFF and JPEG: the EXIF colour space tag, or an ICC profile that names sRGB.
    const bool exif_srgb = spec.get_int_attribute("Exif:ColorSpace", 0) == 1;
    bool icc_srgb = false;
    if (const oiio::ParamValue* icc = spec.find_attribute("ICCProfile")) {
      const auto* bytes = static_cast<const char*>(icc->data());
      const std::string profile(bytes, bytes + icc->type().size() * icc->nvalues());
      icc_srgb = profile.find("sRGB") != std::string::npos;
    }
    info.srgb_tagged = exif_srgb || icc_srgb;
  }
  const std::string unit = spec.get_string_attribute("ResolutionUnit");
  info.dpi_x = DpiFrom(spec.get_float_attribute("XResolution", 0.0f), unit);
  info.dpi_y = DpiFrom(spec.get_float_attribute("YResolution", 0.0f), unit);
  return info;
}

// TIFF's "YYYY:MM:DD HH:MM:SS" in UTC. OIIO would otherwise stamp the local time of writing,
// which makes two writes of the same map differ.
std::string TiffDateTime(std::time_t utc) {
  if (utc == 0) utc = std::time(nullptr);
  std::tm t{};
  gmtime_r(&utc, &t);
  char text[32];
  std::strftime(text, sizeof(text), "%Y:%m:%d %H:%M:%S", &t);
  return text;
}

std::string RandomSuffix() {
  static thread_local std::mt19937_64 rng{std::random_device{}()};
  return std::to_string(rng() % 1000000000ull);
}

// sRGB-decoded value of every 8- and 16-bit code, built once. The reader and the writer's means
// both go through DecodeSample, so one table keeps them identical and saves a pow per sample.
struct SrgbTables {
  std::vector<float> eight, sixteen;
  SrgbTables() : eight(256), sixteen(65536) {
    for (std::size_t c = 0; c < eight.size(); ++c) eight[c] = static_cast<float>(SrgbToLinear(c / 255.0));
    for (std::size_t c = 0; c < sixteen.size(); ++c) sixteen[c] = static_cast<float>(SrgbToLinear(c / 65535.0));
  }
};
const SrgbTables& SrgbDecodeTables() {
  static const SrgbTables tables;
  return tables;
}

// 8-bit sRGB encoding without a pow per sample. Code k + 1 begins at the linear value whose
// encoding is (k + 0.5) / 255 (round to nearest in encoded space). [0, 1] is cut into kBuckets equal
// parts, each holding at most one code boundary (the narrowest gap between boundaries, at the
// bottom of the curve, is 1 / (255 * 12.92) = 3.0e-4 > 1 / 4096), so the code is the bucket's first
// code plus one comparison.
class Srgb8Encoder {
 public:
  Srgb8Encoder() : bounds_(255), first_code_(kBuckets + 1) {
    for (std::size_t k = 0; k < bounds_.size(); ++k) bounds_[k] = SrgbToLinear((k + 0.5) / 255.0);
    for (std::size_t b = 0; b <= kBuckets; ++b) {
      const double start = static_cast<double>(b) / kBuckets;
      first_code_[b] = static_cast<std::uint8_t>(std::upper_bound(bounds_.begin(), bounds_.end(), start) - bounds_.begin());
    }
    for (std::size_t b = 0; b < kBuckets; ++b) {
      if (first_code_[b + 1] - first_code_[b] > 1) throw std::logic_error("Srgb8Encoder: bucket holds two code boundaries");
    }
  }
  // v in [0, 1].
  std::uint32_t Encode(float v) const {
    const double x = v;
    const std::size_t bucket = std::min(static_cast<std::size_t>(x * kBuckets), kBuckets);
    std::uint32_t code = first_code_[bucket];
    if (code < 255 && x >= bounds_[code]) ++code;
    return code;
  }

 private:
  static constexpr std::size_t kBuckets = 4096;
  std::vector<double> bounds_;
  std::vector<std::uint8_t> first_code_;
};

const Srgb8Encoder& Srgb8() {
  static const Srgb8Encoder encoder;
  return encoder;
}

// Interleaved samples of `image` in the file's sample type, encoded and quantised (integer formats).
template <typename T>
std::vector<T> Interleave(const Image& image, const ImageWriteOptions& options) {
  const int c = image.channels();
  const std::size_t pixels = image.pixel_count();
  std::vector<T> out(pixels * static_cast<std::size_t>(c));
  ParallelFor(static_cast<std::size_t>(image.height()), [&](std::size_t row_begin, std::size_t row_end) {
    const std::size_t w = static_cast<std::size_t>(image.width());
    for (int ch = 0; ch < c; ++ch) {
      const std::span<const float> plane = image.plane(ch);
      // sRGB alpha channels stay linear: only colour channels carry the transfer curve.
      const PixelEncoding encoding = ch < 3 ? options.encoding : PixelEncoding::kLinear;
      for (std::size_t i = row_begin * w; i < row_end * w; ++i) {
        if constexpr (std::is_same_v<T, float>) {
          out[i * c + ch] = plane[i];
        } else {
          out[i * c + ch] = static_cast<T>(EncodeSample(plane[i], encoding, options.format));
        }
      }
    }
  });
  return out;
}

}  // namespace

std::uint32_t EncodeSample(float linear, PixelEncoding encoding, SampleFormat format) {
  const float v = std::isnan(linear) ? 0.0f : std::clamp(linear, 0.0f, 1.0f);
  const std::uint32_t max_code = MaxCode(format);
  if (encoding == PixelEncoding::kLinear) {
    return static_cast<std::uint32_t>(std::lround(static_cast<double>(v) * max_code));
  }
  if (format == SampleFormat::kUInt8) return Srgb8().Encode(v);
  return static_cast<std::uint32_t>(std::lround(LinearToSrgb(static_cast<double>(v)) * max_code));
}

float DecodeSample(std::uint32_t code, PixelEncoding encoding, SampleFormat format) {
  const std::uint32_t max_code = MaxCode(format);
  code = std::min(code, max_code);
  if (encoding == PixelEncoding::kSrgb) {
    return format == SampleFormat::kUInt8 ? SrgbDecodeTables().eight[code] : SrgbDecodeTables().sixteen[code];
  }
  return static_cast<float>(static_cast<double>(code) / max_code);
}

void WriteImageFile(const Image& image, const fs::path& path, const ImageWriteOptions& options) {
  const int w = image.width(), h = image.height(), c = image.channels();
  if (w <= 0 || h <= 0 || c <= 0) {
    throw InputError(path.string(), "", "an image with at least one pixel and channel to write");
  }
  const std::string ext = Lower(path.extension().string());
  const bool integer = options.format != SampleFormat::kFloat32;
  if (ext == ".png" && !integer) throw InputError(path.string(), "", "8- or 16-bit samples for PNG (float needs .exr)");
  if (ext == ".exr" && integer) throw InputError(path.string(), "", "float samples for EXR (8/16-bit need .png or .tif)");

  oiio::ImageSpec spec(w, h, c, ToTypeDesc(options.format));
  // Only sRGB-encoded integer files get a colour tag; data maps and float files carry none, so no
  // reader applies a gamma to values that are not colours.
  if (integer && options.encoding == PixelEncoding::kSrgb) spec.attribute("oiio:ColorSpace", "sRGB");
  const double dpi_y = options.dpi_y > 0.0 ? options.dpi_y : options.dpi;
  if (options.dpi > 0.0 && ext != ".exr") {
    spec.attribute("XResolution", static_cast<float>(options.dpi));
    spec.attribute("YResolution", static_cast<float>(dpi_y));
    spec.attribute("ResolutionUnit", "in");
  }
  if (ext == ".exr" || ext == ".tif" || ext == ".tiff") spec.attribute("compression", "zip");
  if (ext == ".tif" || ext == ".tiff") spec.attribute("DateTime", TiffDateTime(options.modified_utc));
  // OIIO's EXR writer stamps the current time unless DateTime is set; empty writes no time.
  if (ext == ".exr") spec.attribute("DateTime", "");
  // Maps hold straight (unassociated) alpha, as PNG and U3M expect; without this OIIO would divide
  // the colour by alpha on the way out.
  spec.attribute("oiio:UnassociatedAlpha", 1);

  std::vector<std::uint8_t> bytes8;
  std::vector<std::uint16_t> bytes16;
  std::vector<float> floats;
  const void* pixels = nullptr;
  switch (options.format) {
    case SampleFormat::kUInt8: bytes8 = Interleave<std::uint8_t>(image, options); pixels = bytes8.data(); break;
    case SampleFormat::kUInt16: bytes16 = Interleave<std::uint16_t>(image, options); pixels = bytes16.data(); break;
    case SampleFormat::kFloat32: floats = Interleave<float>(image, options); pixels = floats.data(); break;
  }

  // Temporary name keeps the extension so OIIO picks the right writer.
  fs::path temp = path;
  std::string temp_name = ".";  // appended piecewise: GCC 12 warns falsely (-Wrestrict) on "." + string
  temp_name += path.stem().string();
  temp_name += ".partial-" + RandomSuffix();
  temp_name += path.extension().string();
  temp.replace_filename(temp_name);
  {
    auto out = oiio::ImageOutput::create(temp.string());
    if (!out) throw InputError(path.string(), "", "a writable image format (.png, .tif, .exr): " + oiio::geterror());
    if (!out->open(temp.string(), spec) || !out->write_image(ToTypeDesc(options.format), pixels) || !out->close()) {
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

namespace {
// Opens with straight alpha kept as stored (OIIO would otherwise premultiply PNG and TIFF alpha).
std::unique_ptr<oiio::ImageInput> OpenInput(const fs::path& path) {
  oiio::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  return oiio::ImageInput::open(path.string(), &config);
}
}  // namespace

ImageReadInfo ReadImageInfo(const fs::path& path) {
  auto in = OpenInput(path);
  if (!in) throw InputError(path.string(), "", "a readable image (PNG, TIFF, EXR, JPEG): " + oiio::geterror());
  return InfoFromSpec(in->spec(), path, std::string(in->format_name()) == "png");
}

Image ReadImageFile(const fs::path& path, PixelEncoding encoding, ImageReadInfo* info_out) {
  auto in = OpenInput(path);
  if (!in) throw InputError(path.string(), "", "a readable image (PNG, TIFF, EXR, JPEG): " + oiio::geterror());
  const oiio::ImageSpec& spec = in->spec();
  const ImageReadInfo info = InfoFromSpec(spec, path, std::string(in->format_name()) == "png");
  if (info_out) *info_out = info;
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0) {
    throw InputError(path.string(), "", "an image with a positive size");
  }
  // Refuse absurd headers before allocating (a 36000 x 36000 PNG header is a few bytes): 2^30
  // samples (4 GiB as float) is far above any texture a scan writes (36 MP RGBA is 1.4e8).
  constexpr std::size_t kMaxValues = std::size_t{1} << 30;
  const std::size_t values = static_cast<std::size_t>(spec.width) * spec.height * spec.nchannels;
  if (values > kMaxValues) {
    throw InputError(path.string(), "", "an image of at most 2^30 samples, header says " +
                                            std::to_string(spec.width) + "x" + std::to_string(spec.height) +
                                            "x" + std::to_string(spec.nchannels));
  }
  const int c = spec.nchannels;
  Image image;
  try {
    image = Image(spec.width, spec.height, c);
  } catch (const std::bad_alloc&) {
    throw InputError(path.string(), "", "an image that fits in memory, header says " + std::to_string(spec.width) +
                                            "x" + std::to_string(spec.height) + "x" + std::to_string(c));
  }
  const std::size_t w = static_cast<std::size_t>(spec.width);
  // Integer files are read as their codes and decoded with DecodeSample, the exact inverse of the
  // writer's quantiser; everything else is converted to float by OIIO and taken as linear.
  auto decode_rows = [&](auto sample_of) {
    ParallelFor(static_cast<std::size_t>(spec.height), [&](std::size_t row_begin, std::size_t row_end) {
      for (int ch = 0; ch < c; ++ch) {
        const std::span<float> plane = image.plane(ch);
        const PixelEncoding channel_encoding = ch < 3 ? encoding : PixelEncoding::kLinear;
        for (std::size_t i = row_begin * w; i < row_end * w; ++i) {
          plane[i] = sample_of(i * c + ch, channel_encoding);
        }
      }
    });
  };
  if (info.format == SampleFormat::kUInt8 || info.format == SampleFormat::kUInt16) {
    const bool eight = info.format == SampleFormat::kUInt8;
    std::vector<std::uint8_t> codes8;
    std::vector<std::uint16_t> codes16;
    void* buffer = nullptr;
    if (eight) {
      codes8.resize(values);
      buffer = codes8.data();
    } else {
      codes16.resize(values);
      buffer = codes16.data();
    }
    if (!in->read_image(0, 0, 0, c, ToTypeDesc(info.format), buffer)) {
      throw InputError(path.string(), "", "complete image data: " + in->geterror());
    }
    decode_rows([&](std::size_t k, PixelEncoding e) {
      return DecodeSample(eight ? codes8[k] : codes16[k], e, info.format);
    });
  } else {
    std::vector<float> interleaved(values);
    if (!in->read_image(0, 0, 0, c, oiio::TypeDesc::FLOAT, interleaved.data())) {
      throw InputError(path.string(), "", "complete image data: " + in->geterror());
    }
    decode_rows([&](std::size_t k, PixelEncoding) { return interleaved[k]; });
  }
  in->close();
  // The pitch stays 0: a camera frame's 72 or 300 dpi tag says nothing about the sample plane.
  // ReadTextureMap takes the pitch from the dpi, where it is meant.
  return image;
}

}  // namespace u3mscan
