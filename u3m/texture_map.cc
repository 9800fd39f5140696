#include "u3m/texture_map.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include "core/error.h"
#include "core/parallel.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

constexpr double kMmPerInch = 25.4;
// Resolution tags that differ by less than this (relative) are the same pitch: PNG stores whole
// pixels per metre, so 300 dpi comes back as 299.9994.
constexpr double kSamePitchTolerance = 1e-3;

PixelEncoding ChannelEncoding(MapKind kind, int channel) {
  return kind == MapKind::kColour && channel < 3 ? PixelEncoding::kSrgb : PixelEncoding::kLinear;
}

// Normal components live in [-1, 1]; files hold (n + 1) / 2. These two are the only place the
// mapping is written down, so the writer, the reader and the means agree to the last bit.
float EncodeNormal(float n) { return (n + 1.0f) * 0.5f; }
float DecodeNormal(float v) { return 2.0f * v - 1.0f; }

void CheckChannels(const Image& map, MapKind kind, const std::string& file) {
  const int c = map.channels();
  if (kind == MapKind::kNormal && c != 3) {
    throw InputError(file, "", "a normal map with 3 channels (x, y, z), got " + std::to_string(c));
  }
  if (kind == MapKind::kColour && c != 3 && c != 4) {
    throw InputError(file, "", "a colour map with 3 (RGB) or 4 (RGBA) channels, got " + std::to_string(c));
  }
  if (c <= 0 || map.pixel_count() == 0) throw InputError(file, "", "a map with at least one pixel and channel");
}

MapGeometry GeometryOrPixels(int width, int height, double pitch_x_mm, double pitch_y_mm) {
  if (pitch_x_mm > 0.0 && pitch_y_mm > 0.0 && std::isfinite(pitch_x_mm) && std::isfinite(pitch_y_mm)) {
    return GeometryFromPitch(width, height, pitch_x_mm, pitch_y_mm);
  }
  MapGeometry g;
  g.width_px = width;
  g.height_px = height;
  return g;
}

}  // namespace

MapGeometry GeometryFromPitch(int width_px, int height_px, double pitch_x_mm, double pitch_y_mm) {
  if (width_px <= 0 || height_px <= 0 || !(pitch_x_mm > 0.0) || !(pitch_y_mm > 0.0) || !std::isfinite(pitch_x_mm) ||
      !std::isfinite(pitch_y_mm)) {
    throw std::invalid_argument("GeometryFromPitch: needs positive sizes and pitches, got " + std::to_string(width_px) +
                                "x" + std::to_string(height_px) + " px at " + std::to_string(pitch_x_mm) + " x " +
                                std::to_string(pitch_y_mm) + " mm");
  }
  MapGeometry g;
  g.width_px = width_px;
  g.height_px = height_px;
  g.width_mm = width_px * pitch_x_mm;
  g.height_mm = height_px * pitch_y_mm;
  g.dpi_x = kMmPerInch / pitch_x_mm;
  g.dpi_y = kMmPerInch / pitch_y_mm;
  return g;
}

MapGeometry GeometryOf(const Image& image) {
  return GeometryFromPitch(image.width(), image.height(), image.pitch_mm(), image.pitch_mm());
}

float QuantisedValue(float value, MapKind kind, int channel, SampleFormat format) {
  if (format == SampleFormat::kFloat32) return value;
  const PixelEncoding encoding = ChannelEncoding(kind, channel);
  if (kind == MapKind::kNormal) {
    return DecodeNormal(DecodeSample(EncodeSample(EncodeNormal(value), encoding, format), encoding, format));
  }
  return DecodeSample(EncodeSample(value, encoding, format), encoding, format);
}

MapGeometry WriteTextureMap(const Image& map, MapKind kind, const fs::path& path, SampleFormat format,
                            std::time_t modified_utc) {
  CheckChannels(map, kind, path.string());
  ImageWriteOptions options;
  options.format = format;
  options.modified_utc = modified_utc;
  options.encoding = kind == MapKind::kColour ? PixelEncoding::kSrgb : PixelEncoding::kLinear;
  const bool metric = map.pitch_mm() > 0.0 && std::isfinite(map.pitch_mm());
  if (metric) options.dpi = kMmPerInch / map.pitch_mm();
  if (kind == MapKind::kNormal) {
    Image encoded(map.width(), map.height(), map.channels(), 0.0f, map.pitch_mm());
    ParallelFor(map.data().size(), [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) encoded.data()[i] = EncodeNormal(map.data()[i]);
    });
    WriteImageFile(encoded, path, options);
  } else {
    WriteImageFile(map, path, options);
  }
  return GeometryOrPixels(map.width(), map.height(), metric ? map.pitch_mm() : 0.0, metric ? map.pitch_mm() : 0.0);
}

Image ReadTextureMap(const fs::path& path, MapKind kind, TextureFileInfo* info_out) {
  TextureFileInfo info;
  Image map = ReadImageFile(path, kind == MapKind::kColour ? PixelEncoding::kSrgb : PixelEncoding::kLinear, &info.file);
  if (kind == MapKind::kNormal) {
    if (map.channels() < 3) {
      throw InputError(path.string(), "", "a normal map with 3 channels (x, y, z), got " +
                                              std::to_string(map.channels()));
    }
    for (int ch = 0; ch < 3; ++ch) {
      for (float& v : map.plane(ch)) v = DecodeNormal(v);
    }
  }
  const double dpi_x = info.file.dpi_x, dpi_y = info.file.dpi_y;
  const double pitch_x = dpi_x > 0.0 ? kMmPerInch / dpi_x : 0.0;
  const double pitch_y = dpi_y > 0.0 ? kMmPerInch / dpi_y : 0.0;
  info.geometry = GeometryOrPixels(map.width(), map.height(), pitch_x, pitch_y);
  if (pitch_x > 0.0 && pitch_y > 0.0 && std::abs(pitch_x - pitch_y) <= kSamePitchTolerance * pitch_x) {
    map.set_pitch_mm(pitch_x);
  }
  if (info_out) *info_out = info;
  return map;
}

std::vector<double> MapChannelMeans(const Image& map, MapKind kind, SampleFormat format) {
  const int c = map.channels();
  std::vector<double> means(static_cast<std::size_t>(c), 0.0);
  if (map.pixel_count() == 0) return means;
  const std::size_t w = static_cast<std::size_t>(map.width());
  const std::size_t h = static_cast<std::size_t>(map.height());
  // Row sums first, then the rows in order: the result does not depend on the thread count.
  std::vector<double> row_sums(h * static_cast<std::size_t>(c), 0.0);
  ParallelFor(h, [&](std::size_t row_begin, std::size_t row_end) {
    for (int ch = 0; ch < c; ++ch) {
      const std::span<const float> plane = map.plane(ch);
      for (std::size_t row = row_begin; row < row_end; ++row) {
        double sum = 0.0;
        for (std::size_t i = row * w; i < (row + 1) * w; ++i) sum += QuantisedValue(plane[i], kind, ch, format);
        row_sums[static_cast<std::size_t>(ch) * h + row] = sum;
      }
    }
  });
  for (int ch = 0; ch < c; ++ch) {
    double sum = 0.0;
    for (std::size_t row = 0; row < h; ++row) sum += row_sums[static_cast<std::size_t>(ch) * h + row];
    means[static_cast<std::size_t>(ch)] = sum / static_cast<double>(map.pixel_count());
  }
  return means;
}

double ScalarMapMean(const Image& map, SampleFormat format, double factor, double offset) {
  if (map.channels() <= 0) throw std::invalid_argument("ScalarMapMean: map has no channels");
  // offset + average(channels) * factor is linear in the pixel values, so its mean over the pixels
  // is the same expression of the channel means.
  const std::vector<double> means = MapChannelMeans(map, MapKind::kData, format);
  double average = 0.0;
  for (double m : means) average += m;
  average /= static_cast<double>(means.size());
  return offset + average * factor;
}

std::array<double, 3> ColourMapMean(const Image& map, SampleFormat format, const std::array<double, 3>& factor) {
  if (map.channels() < 3) throw std::invalid_argument("ColourMapMean: needs 3 or 4 channels");
  const std::vector<double> means = MapChannelMeans(map, MapKind::kColour, format);
  return {means[0] * factor[0], means[1] * factor[1], means[2] * factor[2]};
}

std::array<double, 3> NormalMapMean(const Image& map, SampleFormat format) {
  if (map.channels() != 3) throw std::invalid_argument("NormalMapMean: needs 3 channels");
  const std::vector<double> means = MapChannelMeans(map, MapKind::kNormal, format);
  const double length = std::sqrt(means[0] * means[0] + means[1] * means[1] + means[2] * means[2]);
  constexpr double kDegenerateLength = 1e-9;
  if (!(length > kDegenerateLength)) return {0.0, 0.0, 1.0};
  return {means[0] / length, means[1] / length, means[2] / length};
}

TextureImage TextureImageOf(const std::string& relative_path, const MapGeometry& geometry) {
  TextureImage image;
  image.path = relative_path;
  image.width_mm = geometry.width_mm;
  image.height_mm = geometry.height_mm;
  image.dpi_x = geometry.dpi_x;
  image.dpi_y = geometry.dpi_y;
  return image;
}

}  // namespace u3mscan
