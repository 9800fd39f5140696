// Frame decoding: every file kind the contract allows decodes to the same linear values within
// its quantisation; saturation is flagged; bad files are InputErrors naming the file.

#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>
#include <tiffio.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>

#include "capture/dng_writer.h"
#include "capture/frame_decoder.h"
#include "capture_test_util.h"
#include "core/colour.h"
#include "core/error.h"
#include "u3m/image_io.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;
using testing::SmoothRgb;
using testing::TempDir;

constexpr int kSize = 64;
// Quantisation of each container, in linear units.
constexpr double k16BitTolerance = 1.0 / 65535.0;
constexpr double kHalfTolerance = 1e-3;  // EXR written as float by WriteImageFile; kept loose for half
// 8-bit sRGB: half a code step times the largest slope of the sRGB->linear curve (~2.4 at 1.0).
constexpr double kSrgb8Tolerance = 0.5 / 255.0 * 2.5;
// JPEG (OIIO's writer at its best quality) on a smooth image: YCbCr and DCT rounding, measured
// 3.9 sRGB codes.
constexpr double kJpegToleranceCodes = 5.0;

double MaxError(const Image& a, const Image& b) {
  double worst = 0.0;
  for (int k = 0; k < 3; ++k) {
    for (std::size_t i = 0; i < a.pixel_count(); ++i) {
      worst = std::max(worst, std::abs(double(a.plane(k)[i]) - b.plane(k)[i]));
    }
  }
  return worst;
}

bool AnySaturated(const DecodedFrame& f) {
  return std::any_of(f.saturated.begin(), f.saturated.end(), [](auto s) { return s != 0; });
}

void WriteJpeg(const Image& linear, const fs::path& path) {
  std::vector<unsigned char> pixels(linear.pixel_count() * 3);
  for (std::size_t i = 0; i < linear.pixel_count(); ++i) {
    for (int k = 0; k < 3; ++k) {
      pixels[i * 3 + k] = static_cast<unsigned char>(std::lround(LinearToSrgb(linear.plane(k)[i]) * 255.0f));
    }
  }
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out);
  OIIO::ImageSpec spec(linear.width(), linear.height(), 3, OIIO::TypeDesc::UINT8);
  spec.attribute("Compression", "jpeg:100");
  spec.attribute("jpeg:subsampling", "4:4:4");
  ASSERT_TRUE(out->open(path.string(), spec));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, pixels.data()));
  out->close();
}

// A PNG whose header claims width x height, with a valid CRC and no pixel data.
void WritePngHeader(const fs::path& path, std::uint32_t width, std::uint32_t height) {
  auto be32 = [](std::uint32_t v, unsigned char* p) {
    p[0] = v >> 24;
    p[1] = v >> 16;
    p[2] = v >> 8;
    p[3] = v;
  };
  unsigned char chunk[4 + 4 + 13 + 4];
  be32(13, chunk);
  std::memcpy(chunk + 4, "IHDR", 4);
  be32(width, chunk + 8);
  be32(height, chunk + 12);
  chunk[16] = 8;  // bit depth
  chunk[17] = 2;  // RGB
  chunk[18] = chunk[19] = chunk[20] = 0;
  be32(static_cast<std::uint32_t>(crc32(0, chunk + 4, 17)), chunk + 21);
  std::ofstream out(path, std::ios::binary);
  const unsigned char signature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  out.write(reinterpret_cast<const char*>(signature), 8);
  out.write(reinterpret_cast<const char*>(chunk), sizeof chunk);
}

void Truncate(const fs::path& path, double fraction) {
  fs::resize_file(path, static_cast<std::uintmax_t>(fs::file_size(path) * fraction));
}

// Expects an InputError whose message names `path`; returns its expectation part.
std::string ExpectInputError(const fs::path& path, const FrameDecodeOptions& options = {}) {
  try {
    DecodeFrame(path, options);
    ADD_FAILURE() << "decoded " << path;
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), path.string()) << e.what();
    return e.expected();
  }
  return "";
}

// Points the (single) strip of a little-endian TIFF/DNG at the last 100 bytes of the file: the
// header and IFD stay valid, the pixel data runs past the end, as in a file cut short.
void MoveStripToEndOfFile(const fs::path& path) {
  std::fstream f(path, std::ios::binary | std::ios::in | std::ios::out);
  auto u16 = [&](std::streamoff at) {
    unsigned char b[2];
    f.seekg(at);
    f.read(reinterpret_cast<char*>(b), 2);
    return static_cast<std::uint32_t>(b[0] | b[1] << 8);
  };
  auto u32 = [&](std::streamoff at) { return u16(at) | u16(at + 2) << 16; };
  const std::uint32_t ifd = u32(4);
  const std::uint32_t entries = u16(ifd);
  const std::uint32_t target = static_cast<std::uint32_t>(fs::file_size(path) - 100);
  for (std::uint32_t i = 0; i < entries; ++i) {
    const std::streamoff entry = ifd + 2 + 12 * i;
    if (u16(entry) != TIFFTAG_STRIPOFFSETS) continue;
    ASSERT_EQ(u32(entry + 4), 1u) << "one strip expected";
    const unsigned char b[4] = {static_cast<unsigned char>(target), static_cast<unsigned char>(target >> 8),
                                static_cast<unsigned char>(target >> 16), static_cast<unsigned char>(target >> 24)};
    f.seekp(entry + 8);
    f.write(reinterpret_cast<const char*>(b), 4);
    return;
  }
  FAIL() << "no StripOffsets in " << path;
}

class FrameDecoder : public ::testing::Test {
 protected:
  TempDir dir_;
  const Image truth_ = SmoothRgb(kSize, kSize, 0.02f, 0.9f);
};

TEST_F(FrameDecoder, Linear16BitTiffAndPng) {
  for (const char* name : {"f.tif", "f.png"}) {
    const fs::path path = dir_.path() / name;
    WriteImageFile(truth_, path, {SampleFormat::kUInt16, PixelEncoding::kLinear});
    const DecodedFrame f = DecodeFrame(path);
    EXPECT_EQ(f.encoding, FrameEncoding::kLinear) << name;
    EXPECT_LE(MaxError(f.rgb, truth_), k16BitTolerance) << name;
    EXPECT_FALSE(AnySaturated(f)) << name;
    const FrameHeader h = ReadFrameHeader(path);
    EXPECT_EQ(h.width, kSize);
    EXPECT_EQ(h.encoding, FrameEncoding::kLinear);
  }
}

TEST_F(FrameDecoder, Exr) {
  const fs::path path = dir_.path() / "f.exr";
  WriteImageFile(truth_, path, {SampleFormat::kFloat32, PixelEncoding::kLinear});
  const DecodedFrame f = DecodeFrame(path);
  EXPECT_EQ(f.encoding, FrameEncoding::kLinear);
  EXPECT_LE(MaxError(f.rgb, truth_), kHalfTolerance);
}

TEST_F(FrameDecoder, EightBitPngIsSrgbLinearised) {
  const fs::path path = dir_.path() / "f.png";
  WriteImageFile(truth_, path, {SampleFormat::kUInt8, PixelEncoding::kSrgb});
  const DecodedFrame f = DecodeFrame(path);
  EXPECT_EQ(f.encoding, FrameEncoding::kSrgb);
  EXPECT_LE(MaxError(f.rgb, truth_), kSrgb8Tolerance);
}

TEST_F(FrameDecoder, JpegIsSrgbLinearised) {
  const fs::path path = dir_.path() / "f.jpg";
  WriteJpeg(truth_, path);
  const DecodedFrame f = DecodeFrame(path);
  EXPECT_EQ(f.encoding, FrameEncoding::kSrgb);
  // Compared where JPEG's error lives: in sRGB code values.
  double worst_codes = 0;
  for (int k = 0; k < 3; ++k) {
    for (std::size_t i = 0; i < truth_.pixel_count(); ++i) {
      const double decoded = LinearToSrgb(double(f.rgb.plane(k)[i])), truth = LinearToSrgb(double(truth_.plane(k)[i]));
      worst_codes = std::max(worst_codes, std::abs(decoded - truth) * 255.0);
    }
  }
  EXPECT_LE(worst_codes, kJpegToleranceCodes);
}

TEST_F(FrameDecoder, AllContainersAgreeWithTheDng) {
  // The same linear scene as DNG, 16-bit TIFF and EXR: the RAW path agrees with the others
  // within demosaicing error (interior).
  const fs::path dng = dir_.path() / "f.dng", tif = dir_.path() / "f.tif", exr = dir_.path() / "f.exr";
  WriteDng(dng, MosaicFromLinearRgb(truth_, CfaPattern::kRggb, 0, 65535), kSize, kSize);
  WriteImageFile(truth_, tif, {SampleFormat::kUInt16, PixelEncoding::kLinear});
  WriteImageFile(truth_, exr, {SampleFormat::kFloat32, PixelEncoding::kLinear});
  const DecodedFrame a = DecodeFrame(dng), b = DecodeFrame(tif), c = DecodeFrame(exr);
  constexpr double kDemosaicTolerance = 5e-3;
  constexpr int kBorder = 3;
  for (int k = 0; k < 3; ++k) {
    for (int r = kBorder; r < kSize - kBorder; ++r) {
      for (int col = kBorder; col < kSize - kBorder; ++col) {
        ASSERT_NEAR(a.rgb.at(k, r, col), b.rgb.at(k, r, col), kDemosaicTolerance);
        ASSERT_NEAR(c.rgb.at(k, r, col), b.rgb.at(k, r, col), kHalfTolerance);
      }
    }
  }
}

TEST_F(FrameDecoder, GreyFileFeedsAllThreeChannels) {
  const fs::path path = dir_.path() / "grey.tif";
  WriteImageFile(Image(kSize, kSize, 1, 0.25f), path, {SampleFormat::kUInt16, PixelEncoding::kLinear});
  const DecodedFrame f = DecodeFrame(path);
  ASSERT_EQ(f.rgb.channels(), 3);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(f.rgb.at(k, 5, 5), 0.25, k16BitTolerance);
}

TEST_F(FrameDecoder, SaturationIsFlagged) {
  Image img = truth_;
  img.at(0, 10, 12) = 1.0f;  // one red value at the container's full scale
  for (const char* name : {"s.tif", "s.png"}) {
    const fs::path path = dir_.path() / name;
    WriteImageFile(img, path, {SampleFormat::kUInt16, PixelEncoding::kLinear});
    const DecodedFrame f = DecodeFrame(path);
    EXPECT_TRUE(f.IsSaturated(10, 12)) << name;
    EXPECT_EQ(std::count(f.saturated.begin(), f.saturated.end(), 1), 1) << name;
  }
  const fs::path png8 = dir_.path() / "s8.png";
  WriteImageFile(img, png8, {SampleFormat::kUInt8, PixelEncoding::kSrgb});
  EXPECT_TRUE(DecodeFrame(png8).IsSaturated(10, 12));

  // Float EXR has no ceiling of its own: 2.0 is data unless the manifest gives a white level.
  img.at(1, 20, 20) = 2.0f;
  img.at(2, 30, 30) = std::numeric_limits<float>::quiet_NaN();
  const fs::path exr = dir_.path() / "s.exr";
  WriteImageFile(img, exr, {SampleFormat::kFloat32, PixelEncoding::kLinear});
  const DecodedFrame e = DecodeFrame(exr);
  EXPECT_FALSE(e.IsSaturated(20, 20));
  EXPECT_NEAR(e.rgb.at(1, 20, 20), 2.0, kHalfTolerance);
  EXPECT_TRUE(e.IsSaturated(30, 30));  // not finite: never data
  FrameDecodeOptions white;
  white.response = SensorResponse{0.0, 1.5};
  EXPECT_TRUE(DecodeFrame(exr, white).IsSaturated(20, 20));
}

TEST_F(FrameDecoder, ResponseMapsLinearCodes) {
  // A 16-bit sensor file with black at 4096 and white at 61440 codes.
  constexpr double kBlack = 4096, kWhite = 61440;
  Image img(kSize, kSize, 3, 0.5f);
  img.at(1, 3, 4) = static_cast<float>(62000.0 / 65535.0);
  const fs::path path = dir_.path() / "r.tif";
  WriteImageFile(img, path, {SampleFormat::kUInt16, PixelEncoding::kLinear});
  FrameDecodeOptions opt;
  opt.response = SensorResponse{kBlack, kWhite};
  const DecodedFrame f = DecodeFrame(path, opt);
  const double code = std::round(0.5 * 65535.0);
  EXPECT_NEAR(f.rgb.at(0, 0, 0), (code - kBlack) / (kWhite - kBlack), 1e-5);
  EXPECT_TRUE(f.IsSaturated(3, 4));
  EXPECT_FALSE(f.IsSaturated(3, 5));
}

TEST_F(FrameDecoder, RegionEqualsCropOfFullRead) {
  const fs::path tif = dir_.path() / "f.tif", exr = dir_.path() / "f.exr", dng = dir_.path() / "f.dng";
  const fs::path png8 = dir_.path() / "f8.png";
  WriteImageFile(truth_, tif, {SampleFormat::kUInt16, PixelEncoding::kLinear});
  WriteImageFile(truth_, exr, {SampleFormat::kFloat32, PixelEncoding::kLinear});
  WriteImageFile(truth_, png8, {SampleFormat::kUInt8, PixelEncoding::kSrgb});
  Image bright = truth_;
  bright.at(0, 40, 40) = 1.0f;  // a saturated photosite inside the region
  WriteDng(dng, MosaicFromLinearRgb(bright, CfaPattern::kRggb, 256, 4095), kSize, kSize,
           [] {
             DngWriteOptions o;
             o.black_level = 256;
             o.white_level = 4095;
             return o;
           }());
  const int x = 7, y = 13, w = 41, h = 35;
  for (const fs::path& path : {tif, exr, dng, png8}) {
    const DecodedFrame full = DecodeFrame(path);
    const DecodedFrame part = DecodeFrameRegion(path, {}, x, y, w, h);
    ASSERT_EQ(part.rgb.width(), w);
    ASSERT_EQ(part.rgb.height(), h);
    for (int r = 0; r < h; ++r) {
      for (int c = 0; c < w; ++c) {
        for (int k = 0; k < 3; ++k) ASSERT_EQ(part.rgb.at(k, r, c), full.rgb.at(k, y + r, x + c)) << path;
        ASSERT_EQ(part.IsSaturated(r, c), full.IsSaturated(y + r, x + c)) << path;
      }
    }
    EXPECT_THROW(DecodeFrameRegion(path, {}, 30, 30, 40, 10), std::out_of_range) << path;
  }
}

// A 16-bit RGBA PNG: the decoder reads the first three channels.
void WriteRgbaPng(const Image& img, const fs::path& path) {
  std::vector<std::uint16_t> pixels(img.pixel_count() * 4, 65535);
  for (std::size_t i = 0; i < img.pixel_count(); ++i) {
    for (int k = 0; k < 3; ++k) pixels[i * 4 + k] = static_cast<std::uint16_t>(std::lround(img.plane(k)[i] * 65535.0f));
  }
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out);
  OIIO::ImageSpec spec(img.width(), img.height(), 4, OIIO::TypeDesc::UINT16);
  ASSERT_TRUE(out->open(path.string(), spec)) << out->geterror();
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT16, pixels.data()));
  out->close();
}

// An uncompressed 16-bit TIFF (WriteImageFile compresses TIFF with zip).
void WriteUncompressedTiff(const Image& img, const fs::path& path) {
  std::vector<std::uint16_t> pixels(img.pixel_count() * 3);
  for (std::size_t i = 0; i < img.pixel_count(); ++i) {
    for (int k = 0; k < 3; ++k) pixels[i * 3 + k] = static_cast<std::uint16_t>(std::lround(img.plane(k)[i] * 65535.0f));
  }
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out);
  OIIO::ImageSpec spec(img.width(), img.height(), 3, OIIO::TypeDesc::UINT16);
  spec.attribute("compression", "none");
  ASSERT_TRUE(out->open(path.string(), spec)) << out->geterror();
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT16, pixels.data()));
  out->close();
}

TEST_F(FrameDecoder, WholeDecodesOfPngJpegAndCompressedTiffCropToTheRegionReadsBitForBit) {
  // Capture keeps such frames whole as 16-bit codes and a code table (CompactFrame); every crop
  // must give the floats and flags a region read of the file gives.
  Image img = truth_;
  img.at(0, 10, 12) = 1.0f;  // at the container's full scale: saturated
  img.at(1, 60, 3) = 1.0f;   // in the last rows
  const fs::path png16 = dir_.path() / "w16.png", png8 = dir_.path() / "w8.png", grey = dir_.path() / "wg.png";
  const fs::path rgba = dir_.path() / "wa.png", jpg = dir_.path() / "w.jpg";
  const fs::path tif16 = dir_.path() / "w16.tif", tif8 = dir_.path() / "w8.tif";  // zip
  WriteImageFile(img, tif16, {SampleFormat::kUInt16, PixelEncoding::kLinear});
  WriteImageFile(img, tif8, {SampleFormat::kUInt8, PixelEncoding::kSrgb});
  WriteImageFile(img, png16, {SampleFormat::kUInt16, PixelEncoding::kLinear});
  WriteImageFile(img, png8, {SampleFormat::kUInt8, PixelEncoding::kSrgb});
  Image grey_img(kSize, kSize, 1, 0.0f);
  for (std::size_t i = 0; i < grey_img.pixel_count(); ++i) grey_img.plane(0)[i] = img.plane(1)[i];
  WriteImageFile(grey_img, grey, {SampleFormat::kUInt16, PixelEncoding::kLinear});
  WriteRgbaPng(img, rgba);
  WriteJpeg(img, jpg);
  FrameDecodeOptions levels;  // a sensor response: black and white levels in codes
  levels.response = SensorResponse{4096.0, 52000.0};
  const std::array<std::array<int, 4>, 3> regions = {{{7, 13, 41, 35}, {0, 40, kSize, kSize - 40}, {50, 0, 14, 64}}};
  for (const fs::path& path : {png16, png8, grey, rgba, jpg, tif16, tif8}) {
    ASSERT_TRUE(ReadFrameHeader(path).keep_whole) << path;
    for (const FrameDecodeOptions& options : {FrameDecodeOptions{}, levels}) {
      const CompactFrame whole = DecodeWholeFrame(path, options);
      ASSERT_EQ(whole.width, kSize);
      ASSERT_EQ(whole.height, kSize);
      EXPECT_EQ(whole.bytes(), static_cast<std::size_t>(kSize) * kSize * 7 + whole.linear_of_code.size() * sizeof(float));
      int saturated = 0;
      for (const auto& [x, y, w, h] : regions) {
        const DecodedFrame part = whole.Crop(x, y, w, h);
        const DecodedFrame read = DecodeFrameRegion(path, options, x, y, w, h);
        EXPECT_EQ(part.encoding, read.encoding) << path;
        for (int r = 0; r < h; ++r) {
          for (int c = 0; c < w; ++c) {
            for (int k = 0; k < 3; ++k) ASSERT_EQ(part.rgb.at(k, r, c), read.rgb.at(k, r, c)) << path << " " << r << "," << c;
            ASSERT_EQ(part.IsSaturated(r, c), read.IsSaturated(r, c)) << path << " " << r << "," << c;
            saturated += part.IsSaturated(r, c);
          }
        }
      }
      EXPECT_GT(saturated, 0) << path;  // the flags are compared where there are some
    }
  }
  // Uncompressed and float files are read by rows where they lie: not kept whole.
  const fs::path plain_tif = dir_.path() / "wu.tif", float_tif = dir_.path() / "wf.tif", exr = dir_.path() / "w.exr";
  WriteUncompressedTiff(img, plain_tif);
  WriteImageFile(img, float_tif, {SampleFormat::kFloat32, PixelEncoding::kLinear});
  WriteImageFile(img, exr, {SampleFormat::kFloat32, PixelEncoding::kLinear});
  ASSERT_EQ(OIIO::ImageInput::open(plain_tif.string())->spec().get_string_attribute("compression"), "none");
  EXPECT_FALSE(ReadFrameHeader(plain_tif).keep_whole);
  EXPECT_FALSE(ReadFrameHeader(float_tif).keep_whole);
  EXPECT_FALSE(ReadFrameHeader(exr).keep_whole);
  EXPECT_THROW(DecodeWholeFrame(exr), std::invalid_argument);
  const fs::path dng = dir_.path() / "w.dng";
  WriteDng(dng, MosaicFromLinearRgb(truth_, CfaPattern::kRggb, 0, 65535), kSize, kSize);
  EXPECT_TRUE(ReadFrameHeader(dng).keep_whole);
  // A cut PNG is an InputError naming the file, as a region read of it is.
  Truncate(png16, 0.6);
  try {
    DecodeWholeFrame(png16);
    ADD_FAILURE() << "decoded a truncated PNG whole";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), png16.string()) << e.what();
  }
}

// A tiled float file (EXR or TIFF) with tiles that do not divide the image size.
void WriteTiled(const Image& img, const fs::path& path, int tile) {
  std::vector<float> pixels(img.pixel_count() * 3);
  for (std::size_t i = 0; i < img.pixel_count(); ++i) {
    for (int k = 0; k < 3; ++k) pixels[i * 3 + k] = img.plane(k)[i];
  }
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out);
  OIIO::ImageSpec spec(img.width(), img.height(), 3, OIIO::TypeDesc::FLOAT);
  spec.tile_width = tile;
  spec.tile_height = tile;
  ASSERT_TRUE(out->supports("tiles"));
  ASSERT_TRUE(out->open(path.string(), spec)) << out->geterror();
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, pixels.data()));
  out->close();
}

TEST_F(FrameDecoder, TiledFilesReadOnlyTheirTilesAndMatchTheFullRead) {
  constexpr int kTile = 48;  // TIFF tiles are multiples of 16; 64 = 48 + 16: edge tiles are partial
  for (const char* name : {"tiled.exr", "tiled.tif"}) {
    const fs::path path = dir_.path() / name;
    WriteTiled(truth_, path, kTile);
    ASSERT_GT(OIIO::ImageInput::open(path.string())->spec().tile_width, 0) << name;
    const DecodedFrame full = DecodeFrame(path);
    EXPECT_LE(MaxError(full.rgb, truth_), kHalfTolerance) << name;
    for (const auto& [x, y, w, h] : {std::array<int, 4>{7, 13, 41, 35}, std::array<int, 4>{50, 60, 14, 4},
                                     std::array<int, 4>{48, 0, 16, 64}}) {
      const DecodedFrame part = DecodeFrameRegion(path, {}, x, y, w, h);
      for (int r = 0; r < h; ++r) {
        for (int c = 0; c < w; ++c) {
          for (int k = 0; k < 3; ++k) ASSERT_EQ(part.rgb.at(k, r, c), full.rgb.at(k, y + r, x + c)) << name;
        }
      }
    }
  }
}

TEST_F(FrameDecoder, TextFileNamedDng) {
  const fs::path path = dir_.path() / "notes.dng";
  testing::WriteText(path, "this is not a raw file\n");
  ExpectInputError(path);
  EXPECT_THROW(ReadFrameHeader(path), InputError);
}

TEST_F(FrameDecoder, TextFileNamedPng) {
  const fs::path path = dir_.path() / "notes.png";
  testing::WriteText(path, "this is not a png\n");
  ExpectInputError(path);
}

TEST_F(FrameDecoder, MissingFile) { ExpectInputError(dir_.path() / "nothing.tif"); }

TEST_F(FrameDecoder, TruncatedFiles) {
  const fs::path dng = dir_.path() / "t.dng", tif = dir_.path() / "t.tif", png = dir_.path() / "t.png";
  const fs::path exr = dir_.path() / "t.exr", jpg = dir_.path() / "t.jpg";
  WriteDng(dng, MosaicFromLinearRgb(truth_, CfaPattern::kRggb, 0, 65535), kSize, kSize);
  WriteImageFile(truth_, tif, {SampleFormat::kUInt16, PixelEncoding::kLinear});
  WriteImageFile(truth_, png, {SampleFormat::kUInt16, PixelEncoding::kLinear});
  WriteImageFile(truth_, exr, {SampleFormat::kFloat32, PixelEncoding::kLinear});
  WriteJpeg(truth_, jpg);
  for (const fs::path& path : {dng, tif, png, exr, jpg}) {
    Truncate(path, 0.6);
    ExpectInputError(path);
  }
  // A DNG whose directory survives but whose pixel data is cut short (libraw 0.20 checks strip
  // extents of DNGs itself; the decoder's count of bytes read past the end backs up the others).
  const fs::path short_data = dir_.path() / "short.dng";
  WriteDng(short_data, MosaicFromLinearRgb(truth_, CfaPattern::kRggb, 0, 65535), kSize, kSize);
  MoveStripToEndOfFile(short_data);
  const std::string why = ExpectInputError(short_data);
  EXPECT_NE(why.find("truncated"), std::string::npos) << why;
}

TEST_F(FrameDecoder, HugeDimensionHeaders) {
  const fs::path wide = dir_.path() / "wide.png", big = dir_.path() / "big.png";
  WritePngHeader(wide, 1u << 20, 16);   // a side beyond 65536
  WritePngHeader(big, 60000, 60000);    // 3.6 gigapixels
  ExpectInputError(wide);  // libpng refuses the IHDR itself
  ExpectInputError(big);
  EXPECT_THROW(ReadFrameHeader(big), InputError);

  // A DNG whose IFD claims 60000 x 60000 photosites but holds one row.
  const fs::path dng = dir_.path() / "big.dng";
  {
    TIFF* t = TIFFOpen(dng.c_str(), "w");
    ASSERT_NE(t, nullptr);
    const std::uint8_t version[4] = {1, 4, 0, 0};
    const std::uint16_t dim[2] = {2, 2};
    const std::uint8_t cfa[4] = {0, 1, 1, 2};
    TIFFSetField(t, TIFFTAG_SUBFILETYPE, 0);
    TIFFSetField(t, TIFFTAG_IMAGEWIDTH, 60000);
    TIFFSetField(t, TIFFTAG_IMAGELENGTH, 60000);
    TIFFSetField(t, TIFFTAG_BITSPERSAMPLE, 16);
    TIFFSetField(t, TIFFTAG_SAMPLESPERPIXEL, 1);
    TIFFSetField(t, TIFFTAG_PHOTOMETRIC, 32803);
    TIFFSetField(t, TIFFTAG_ROWSPERSTRIP, 60000);
    TIFFSetField(t, TIFFTAG_MAKE, "u3mscan");
    TIFFSetField(t, TIFFTAG_DNGVERSION, version);
    TIFFSetField(t, TIFFTAG_UNIQUECAMERAMODEL, "u3mscan");
    TIFFSetField(t, TIFFTAG_CFAREPEATPATTERNDIM, dim);
    TIFFSetField(t, TIFFTAG_CFAPATTERN, 4, cfa);
    std::vector<std::uint16_t> row(60000, 100);
    TIFFWriteScanline(t, row.data(), 0, 0);
    TIFFClose(t);
  }
  EXPECT_NE(ExpectInputError(dng).find("60000x60000"), std::string::npos);
}

TEST_F(FrameDecoder, CorruptedBytesGiveDataOrInputErrorNeverACrash) {
  // Random bytes overwritten near the header and near the end (where libtiff puts the IFD), with
  // a fixed seed: each case must decode or throw InputError, nothing else.
  constexpr int kCasesPerFile = 40;
  constexpr std::size_t kRegionBytes = 400;
  const fs::path dng = dir_.path() / "c.dng", tif = dir_.path() / "c.tif", png = dir_.path() / "c.png";
  WriteDng(dng, MosaicFromLinearRgb(truth_, CfaPattern::kRggb, 0, 65535), kSize, kSize);
  WriteImageFile(truth_, tif, {SampleFormat::kUInt16, PixelEncoding::kLinear});
  WriteImageFile(truth_, png, {SampleFormat::kUInt8, PixelEncoding::kSrgb});
  std::mt19937 rng(20261122);
  int refused = 0;
  for (const fs::path& original : {dng, tif, png}) {
    std::stringstream bytes;
    bytes << std::ifstream(original, std::ios::binary).rdbuf();
    const std::string clean = bytes.str();
    ASSERT_GT(clean.size(), 2 * kRegionBytes);
    for (int i = 0; i < kCasesPerFile; ++i) {
      std::string data = clean;
      const int flips = 1 + static_cast<int>(rng() % 8);
      for (int j = 0; j < flips; ++j) {
        const std::size_t offset = rng() % kRegionBytes;
        data[(rng() % 2) ? offset : data.size() - 1 - offset] = static_cast<char>(rng());
      }
      const fs::path path = dir_.path() / ("case" + original.extension().string());
      std::ofstream(path, std::ios::binary) << data;
      try {
        const DecodedFrame f = DecodeFrame(path);
        EXPECT_EQ(f.rgb.channels(), 3);
      } catch (const InputError& e) {
        EXPECT_EQ(e.file(), path.string());
        ++refused;
      }
    }
  }
  EXPECT_GT(refused, 0);  // the corruption did reach the parsers
}

}  // namespace
}  // namespace u3mscan
