// Texture map files: encodings, tags, quantisation, geometry and the U3M means.

#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>

#include <cmath>
#include <fstream>
#include <random>
#include <set>

#include "core/colour.h"
#include "core/error.h"
#include "tests/u3m_package/test_util.h"
#include "u3m/image_io.h"
#include "u3m/texture_map.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

constexpr int kSize = 64;
constexpr double kPitchMm = 0.1;         // 254 dpi: a whole number of pixels per metre for PNG
constexpr double kFloatTolerance = 1e-6;  // float32 arithmetic on values near 1
constexpr double kMeanTolerance = 1e-9;   // double sums of identical float values

// Half a code step of each integer format: the most a round trip may move a linear value.
double HalfStep(SampleFormat format) { return format == SampleFormat::kUInt8 ? 0.5 / 255.0 : 0.5 / 65535.0; }

Image RandomMap(int channels, float lo, float hi, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> dist(lo, hi);
  Image image(kSize, kSize, channels, 0.0f, kPitchMm);
  for (float& v : image.data()) v = dist(rng);
  return image;
}

Image RandomNormals(unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> slope(-0.7f, 0.7f);
  Image image(kSize, kSize, 3, 0.0f, kPitchMm);
  for (int r = 0; r < kSize; ++r) {
    for (int c = 0; c < kSize; ++c) {
      const float x = slope(rng), y = slope(rng);
      const float len = std::sqrt(x * x + y * y + 1.0f);
      image.at(0, r, c) = x / len;
      image.at(1, r, c) = y / len;
      image.at(2, r, c) = 1.0f / len;
    }
  }
  return image;
}

// PNG chunk types before the image data, read straight from the file.
std::set<std::string> PngChunks(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::set<std::string> chunks;
  in.seekg(8);
  unsigned char header[8];
  while (in.read(reinterpret_cast<char*>(header), 8)) {
    const std::uint32_t length = (std::uint32_t{header[0]} << 24) | (std::uint32_t{header[1]} << 16) |
                                 (std::uint32_t{header[2]} << 8) | header[3];
    chunks.insert(std::string(reinterpret_cast<char*>(header + 4), 4));
    in.seekg(length + 4, std::ios::cur);
  }
  return chunks;
}

std::vector<std::uint8_t> FileBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

struct FormatCase {
  const char* extension;
  SampleFormat format;
};
const FormatCase kIntegerCases[] = {{".png", SampleFormat::kUInt8}, {".png", SampleFormat::kUInt16},
                                    {".tif", SampleFormat::kUInt8}, {".tif", SampleFormat::kUInt16}};

TEST(TextureMap, DataMapsRoundTripWithinQuantisationAndCarryNoColourTag) {
  TempDir dir;
  const Image map = RandomMap(1, -0.1f, 1.1f, 1);  // out-of-range values are clamped
  for (const FormatCase& fc : kIntegerCases) {
    SCOPED_TRACE(std::string(fc.extension) + (fc.format == SampleFormat::kUInt8 ? " 8-bit" : " 16-bit"));
    const fs::path path = dir.path() / (std::string("roughness") + fc.extension);
    WriteTextureMap(map, MapKind::kData, path, fc.format);
    TextureFileInfo info;
    const Image back = ReadTextureMap(path, MapKind::kData, &info);
    ASSERT_EQ(back.channels(), 1);
    EXPECT_EQ(info.file.format, fc.format);
    EXPECT_FALSE(info.file.srgb_tagged);
    double worst = 0.0;
    for (std::size_t i = 0; i < map.data().size(); ++i) {
      const double expected = std::clamp(map.data()[i], 0.0f, 1.0f);
      worst = std::max(worst, std::abs(back.data()[i] - expected));
      ASSERT_EQ(back.data()[i], QuantisedValue(map.data()[i], MapKind::kData, 0, fc.format)) << i;
    }
    EXPECT_LE(worst, HalfStep(fc.format) + kFloatTolerance);
    EXPECT_NEAR(ScalarMapMean(map, fc.format), back.ChannelMean(0), kMeanTolerance);
    if (std::string(fc.extension) == ".png") {
      const auto chunks = PngChunks(path);
      for (const char* colour_chunk : {"sRGB", "gAMA", "cHRM", "iCCP"}) EXPECT_EQ(chunks.count(colour_chunk), 0u) << colour_chunk;
    }
  }
}

TEST(TextureMap, ColourMapsAreSrgbEncodedAndTagged) {
  TempDir dir;
  Image map = RandomMap(4, 0.0f, 1.0f, 2);  // RGBA: alpha stays linear
  map.at(0, 0, 0) = 0.5f;                    // linear 0.5 is sRGB code 188 in 8 bits
  map.at(3, 0, 0) = 0.5f;                    // alpha 0.5 is code 128
  for (const FormatCase& fc : kIntegerCases) {
    SCOPED_TRACE(std::string(fc.extension) + (fc.format == SampleFormat::kUInt8 ? " 8-bit" : " 16-bit"));
    const fs::path path = dir.path() / (std::string("basecolor") + fc.extension);
    WriteTextureMap(map, MapKind::kColour, path, fc.format);
    TextureFileInfo info;
    const Image back = ReadTextureMap(path, MapKind::kColour, &info);
    EXPECT_TRUE(info.file.srgb_tagged);
    if (std::string(fc.extension) == ".png") {
      EXPECT_EQ(PngChunks(path).count("sRGB"), 1u);
    }
    // The file holds encoded values: read raw, they follow the sRGB curve.
    const Image raw = ReadImageFile(path, PixelEncoding::kLinear);
    const double max_code = fc.format == SampleFormat::kUInt8 ? 255.0 : 65535.0;
    EXPECT_NEAR(raw.at(0, 0, 0), std::round(LinearToSrgb(0.5) * max_code) / max_code, kFloatTolerance);
    EXPECT_NEAR(raw.at(3, 0, 0), std::round(0.5 * max_code) / max_code, kFloatTolerance);
    for (int ch = 0; ch < 4; ++ch) {
      for (std::size_t i = 0; i < map.pixel_count(); ++i) {
        ASSERT_EQ(back.plane(ch)[i], QuantisedValue(map.plane(ch)[i], MapKind::kColour, ch, fc.format));
      }
    }
    // In linear terms a round trip moves a value by at most half a code step times the steepest
    // slope of the sRGB decoding curve, d linear / d encoded = 2.4 / 1.055 at encoded = 1.
    constexpr double kSrgbDecodeMaxSlope = 2.4 / 1.055;
    for (std::size_t i = 0; i < map.pixel_count(); ++i) {
      ASSERT_NEAR(back.plane(0)[i], map.plane(0)[i], HalfStep(fc.format) * kSrgbDecodeMaxSlope + kFloatTolerance);
    }
    const auto mean = ColourMapMean(map, fc.format);
    for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(mean[ch], back.ChannelMean(ch), kMeanTolerance);
  }
}

TEST(TextureMap, NormalMapsAreOpenGlEncoded) {
  TempDir dir;
  Image map(kSize, kSize, 3, 0.0f, kPitchMm);
  // Left half flat, right half tilted towards +Y (up in the image).
  for (int r = 0; r < kSize; ++r) {
    for (int c = 0; c < kSize; ++c) {
      const bool tilted = c >= kSize / 2;
      map.at(0, r, c) = 0.0f;
      map.at(1, r, c) = tilted ? 0.6f : 0.0f;
      map.at(2, r, c) = tilted ? 0.8f : 1.0f;
    }
  }
  const fs::path path = dir.path() / "normal.png";
  WriteTextureMap(map, MapKind::kNormal, path, SampleFormat::kUInt16);
  const Image raw = ReadImageFile(path, PixelEncoding::kLinear);
  constexpr double kStep16 = 1.0 / 65535.0;
  EXPECT_NEAR(raw.at(0, 0, 0), 0.5, kStep16);  // flat: (0.5, 0.5, 1)
  EXPECT_NEAR(raw.at(1, 0, 0), 0.5, kStep16);
  EXPECT_NEAR(raw.at(2, 0, 0), 1.0, kStep16);
  EXPECT_NEAR(raw.at(1, 0, kSize - 1), 0.8, kStep16);  // +Y up = more green
  EXPECT_NEAR(raw.at(2, 0, kSize - 1), 0.9, kStep16);
  EXPECT_FALSE(ReadImageInfo(path).srgb_tagged);
  EXPECT_EQ(PngChunks(path).count("gAMA"), 0u);

  const Image random = RandomNormals(3);
  for (const FormatCase& fc : kIntegerCases) {
    const fs::path p = dir.path() / (std::string("n") + fc.extension);
    WriteTextureMap(random, MapKind::kNormal, p, fc.format);
    const Image back = ReadTextureMap(p, MapKind::kNormal);
    for (std::size_t i = 0; i < random.data().size(); ++i) {
      ASSERT_NEAR(back.data()[i], random.data()[i], 2.0 * HalfStep(fc.format) + kFloatTolerance);
    }
    const auto mean = NormalMapMean(random, fc.format);
    const double bx = back.ChannelMean(0), by = back.ChannelMean(1), bz = back.ChannelMean(2);
    const double len = std::sqrt(bx * bx + by * by + bz * bz);
    EXPECT_NEAR(mean[0], bx / len, kMeanTolerance);
    EXPECT_NEAR(mean[1], by / len, kMeanTolerance);
    EXPECT_NEAR(mean[2], bz / len, kMeanTolerance);
  }
  const auto tilted_mean = NormalMapMean(map, SampleFormat::kFloat32);
  EXPECT_GT(tilted_mean[1], 0.0);
  EXPECT_NEAR(std::hypot(tilted_mean[0], tilted_mean[1], tilted_mean[2]), 1.0, kMeanTolerance);
}

TEST(TextureMap, FloatExrKeepsValuesExactlyAndIsLinear) {
  TempDir dir;
  const Image height = RandomMap(1, -2.0f, 3.0f, 4);  // displacement in mm: outside 0..1 is kept
  const fs::path path = dir.path() / "displacement.exr";
  WriteTextureMap(height, MapKind::kData, path, SampleFormat::kFloat32);
  TextureFileInfo info;
  const Image back = ReadTextureMap(path, MapKind::kData, &info);
  EXPECT_EQ(info.file.format, SampleFormat::kFloat32);
  EXPECT_EQ(back.data(), height.data());

  const Image hdr = RandomMap(3, 0.0f, 4.0f, 5);
  WriteTextureMap(hdr, MapKind::kColour, dir.path() / "basecolor.exr", SampleFormat::kFloat32);
  const Image hdr_back = ReadTextureMap(dir.path() / "basecolor.exr", MapKind::kColour, &info);
  EXPECT_FALSE(info.file.srgb_tagged);
  EXPECT_EQ(hdr_back.data(), hdr.data()) << "float colour maps are linear, no transfer curve";

  const Image normals = RandomNormals(6);
  WriteTextureMap(normals, MapKind::kNormal, dir.path() / "normal.exr", SampleFormat::kFloat32);
  const Image raw = ReadImageFile(dir.path() / "normal.exr", PixelEncoding::kLinear);
  EXPECT_NEAR(raw.data()[0], (normals.data()[0] + 1.0f) / 2.0f, kFloatTolerance) << "EXR normals are (n+1)/2 too";
  const Image normals_back = ReadTextureMap(dir.path() / "normal.exr", MapKind::kNormal);
  for (std::size_t i = 0; i < normals.data().size(); ++i) ASSERT_NEAR(normals_back.data()[i], normals.data()[i], kFloatTolerance);
}

TEST(TextureMap, GeometryFromPixelsAndPitch) {
  const MapGeometry g = GeometryFromPitch(640, 320, 0.1, 0.2);
  EXPECT_EQ(g.width_px, 640);
  EXPECT_DOUBLE_EQ(g.width_mm, 64.0);
  EXPECT_DOUBLE_EQ(g.height_mm, 64.0);
  EXPECT_DOUBLE_EQ(g.dpi_x, 254.0);
  EXPECT_DOUBLE_EQ(g.dpi_y, 127.0);
  // U3M 1.1's check: pixels = mm * dpi / 25.4.
  EXPECT_NEAR(g.width_mm * g.dpi_x / 25.4, 640.0, 1e-9);
  EXPECT_THROW(GeometryFromPitch(64, 64, 0.0, 0.1), std::invalid_argument);
  EXPECT_THROW(GeometryFromPitch(0, 64, 0.1, 0.1), std::invalid_argument);

  TempDir dir;
  Image map(kSize, kSize / 2, 1, 0.25f, 0.0847);  // ~299.88 dpi
  for (const char* ext : {".png", ".tif"}) {
    SCOPED_TRACE(ext);
    const fs::path path = dir.path() / (std::string("m") + ext);
    const MapGeometry written = WriteTextureMap(map, MapKind::kData, path, SampleFormat::kUInt8);
    EXPECT_NEAR(written.width_mm, kSize * 0.0847, 1e-12);
    EXPECT_NEAR(written.dpi_x, 25.4 / 0.0847, 1e-9);
    TextureFileInfo info;
    const Image back = ReadTextureMap(path, MapKind::kData, &info);
    EXPECT_EQ(info.geometry.width_px, kSize);
    EXPECT_EQ(info.geometry.height_px, kSize / 2);
    // PNG keeps whole pixels per metre; TIFF keeps a float.
    constexpr double kDpiRelativeTolerance = 2e-4;
    EXPECT_NEAR(info.geometry.dpi_x, written.dpi_x, written.dpi_x * kDpiRelativeTolerance);
    EXPECT_NEAR(info.geometry.height_mm, written.height_mm, written.height_mm * kDpiRelativeTolerance);
    EXPECT_NEAR(back.pitch_mm(), 0.0847, 0.0847 * kDpiRelativeTolerance);
  }
  const MapGeometry no_pitch = WriteTextureMap(Image(8, 8, 1, 0.5f), MapKind::kData, dir.path() / "n.png",
                                               SampleFormat::kUInt8);
  EXPECT_EQ(no_pitch.width_px, 8);
  EXPECT_EQ(no_pitch.dpi_x, 0.0);
  TextureFileInfo info;
  EXPECT_EQ(ReadTextureMap(dir.path() / "n.png", MapKind::kData, &info).pitch_mm(), 0.0);
  EXPECT_EQ(info.geometry.dpi_x, 0.0);
}

TEST(TextureMap, QuantisedMeanDiffersFromThePlainMeanWhereItMatters) {
  // 0.001 is below half an 8-bit step: the file holds 0 everywhere, so the constant must be 0.
  const Image faint(kSize, kSize, 1, 0.001f, kPitchMm);
  EXPECT_EQ(ScalarMapMean(faint, SampleFormat::kUInt8), 0.0);
  EXPECT_NEAR(ScalarMapMean(faint, SampleFormat::kFloat32), 0.001, kFloatTolerance);
  EXPECT_NEAR(ScalarMapMean(faint, SampleFormat::kUInt16), std::round(0.001 * 65535) / 65535, kMeanTolerance);
  // U3M's scalar value: offset + average(channels) * factor.
  Image two(4, 4, 2, 0.0f);
  for (float& v : two.plane(0)) v = 0.2f;
  for (float& v : two.plane(1)) v = 0.6f;
  EXPECT_NEAR(ScalarMapMean(two, SampleFormat::kFloat32, 2.0, 0.1), 0.1 + 0.4 * 2.0, kFloatTolerance);
  const auto colour = ColourMapMean(Image(4, 4, 3, 0.5f), SampleFormat::kFloat32, {1.0, 0.5, 0.25});
  EXPECT_NEAR(colour[1], 0.25, kFloatTolerance);
}

// The 8-bit sRGB encoder uses a bucket table instead of a pow; it must still round to the nearest
// code in encoded space, and DecodeSample must invert it.
TEST(TextureMap, EncodeSampleRoundsToTheNearestEncodedCode) {
  constexpr int kSteps = 1 << 20;
  constexpr double kTieWidth = 1e-6;  // in codes: float input cannot resolve ties closer than this
  int mismatches = 0;
  for (int i = 0; i <= kSteps; ++i) {
    const float v = static_cast<float>(i) / kSteps;
    for (SampleFormat format : {SampleFormat::kUInt8, SampleFormat::kUInt16}) {
      const double max_code = format == SampleFormat::kUInt8 ? 255.0 : 65535.0;
      const double exact = LinearToSrgb(static_cast<double>(v)) * max_code;
      const auto code = EncodeSample(v, PixelEncoding::kSrgb, format);
      if (code != std::lround(exact) && std::abs(exact - std::floor(exact) - 0.5) > kTieWidth) ++mismatches;
      EXPECT_EQ(EncodeSample(v, PixelEncoding::kLinear, format), std::lround(v * max_code));
      if (i % 4096 == 0) {
        EXPECT_NEAR(DecodeSample(code, PixelEncoding::kSrgb, format), SrgbToLinear(code / max_code), kFloatTolerance);
      }
    }
  }
  EXPECT_EQ(mismatches, 0);
  EXPECT_EQ(EncodeSample(-1.0f, PixelEncoding::kSrgb, SampleFormat::kUInt8), 0u);
  EXPECT_EQ(EncodeSample(2.0f, PixelEncoding::kSrgb, SampleFormat::kUInt8), 255u);
  EXPECT_EQ(EncodeSample(std::nanf(""), PixelEncoding::kSrgb, SampleFormat::kUInt16), 0u);
}

TEST(TextureMap, WritesAreReproducible) {
  TempDir dir;
  const Image map = RandomMap(3, 0.0f, 1.0f, 7);
  constexpr std::time_t kFixedTimeUtc = 1709646330;  // 2024-03-05 13:45:30 UTC
  for (const char* ext : {".png", ".tif", ".exr"}) {
    const SampleFormat format = std::string(ext) == ".exr" ? SampleFormat::kFloat32 : SampleFormat::kUInt8;
    const fs::path a = dir.path() / (std::string("a") + ext), b = dir.path() / (std::string("b") + ext);
    WriteTextureMap(map, MapKind::kColour, a, format, kFixedTimeUtc);
    WriteTextureMap(map, MapKind::kColour, b, format, kFixedTimeUtc + 0);
    EXPECT_EQ(FileBytes(a), FileBytes(b)) << ext << ": same map and time, same bytes (reproducible .u3ma)";
  }
  auto in = OIIO::ImageInput::open((dir.path() / "a.tif").string());
  ASSERT_TRUE(in);
  EXPECT_EQ(in->spec().get_string_attribute("DateTime"), "2024:03:05 13:45:30") << "TIFF time in UTC";
}

TEST(TextureMap, BadRequestsAndBadFilesAreInputErrorsThatWriteNothing) {
  TempDir dir;
  EXPECT_THROW(WriteTextureMap(Image(8, 8, 1, 0.5f), MapKind::kNormal, dir.path() / "n.png", SampleFormat::kUInt8),
               InputError);
  EXPECT_THROW(WriteTextureMap(Image(8, 8, 2, 0.5f), MapKind::kColour, dir.path() / "c.png", SampleFormat::kUInt8),
               InputError);
  EXPECT_THROW(WriteTextureMap(Image(8, 8, 1, 0.5f), MapKind::kData, dir.path() / "f.png", SampleFormat::kFloat32),
               InputError);
  EXPECT_THROW(WriteTextureMap(Image(8, 8, 1, 0.5f), MapKind::kData, dir.path() / "i.exr", SampleFormat::kUInt8),
               InputError);
  EXPECT_THROW(WriteTextureMap(Image(8, 8, 1, 0.5f), MapKind::kData, dir.path() / "x.bmpx", SampleFormat::kUInt8),
               InputError);
  EXPECT_TRUE(fs::is_empty(dir.path()));

  const fs::path garbage = dir.path() / "garbage.png";
  {
    std::ofstream out(garbage, std::ios::binary);
    out << "\x89PNG\r\n\x1a\n not really a png";
  }
  try {
    ReadTextureMap(garbage, MapKind::kColour);
    ADD_FAILURE() << "read a broken PNG";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), garbage.string());
  }
  EXPECT_THROW(ReadTextureMap(dir.path() / "missing.png", MapKind::kData), InputError);
}

}  // namespace
}  // namespace u3mscan
