#include "capture/dng_writer.h"

#include <tiffio.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <system_error>

#include "core/error.h"
#include "core/parallel.h"

namespace u3mscan {
namespace {

namespace fs = std::filesystem;

constexpr int kRowsPerStrip = 64;             // strips of ~64 rows keep readers' buffers small
constexpr std::uint16_t kPhotometricCfa = 32803;  // PhotometricInterpretation "CFA" (TIFF/EP)
constexpr std::uint16_t kIlluminantD65 = 21;      // EXIF LightSource code
constexpr std::uint16_t kCfaLayoutRectangular = 1;

// CFAPattern colour codes (TIFF/EP): 0 red, 1 green, 2 blue; tile read row by row.
std::array<std::uint8_t, 4> PatternCodes(CfaPattern pattern) {
  switch (pattern) {
    case CfaPattern::kRggb: return {0, 1, 1, 2};
    case CfaPattern::kBggr: return {2, 1, 1, 0};
    case CfaPattern::kGrbg: return {1, 0, 2, 1};
    case CfaPattern::kGbrg: return {1, 2, 0, 1};
  }
  return {0, 1, 1, 2};
}

struct TiffCloser {
  void operator()(TIFF* tif) const {
    if (tif) TIFFClose(tif);
  }
};

}  // namespace

int CfaColourAt(CfaPattern pattern, int row, int col) {
  return PatternCodes(pattern)[static_cast<std::size_t>((row & 1) * 2 + (col & 1))];
}

Eigen::Matrix3d LinearSrgbToXyz() {
  // libraw's xyz_rgb (sRGB primaries, D65 white): the same numbers libraw multiplies the DNG's
  // ColorMatrix1 with, so that the default ColorMatrix1 gives libraw an identity camera matrix.
  Eigen::Matrix3d m;
  m << 0.412453, 0.357580, 0.180423,  //
      0.212671, 0.715160, 0.072169,   //
      0.019334, 0.119193, 0.950227;
  return m;
}

std::vector<std::uint16_t> MosaicFromLinearRgb(const Image& rgb, CfaPattern pattern, std::uint16_t black_level,
                                               std::uint16_t white_level) {
  if (rgb.channels() != 3) throw std::invalid_argument("MosaicFromLinearRgb: needs a 3-channel image");
  if (white_level <= black_level) throw std::invalid_argument("MosaicFromLinearRgb: white_level <= black_level");
  const int w = rgb.width(), h = rgb.height();
  std::vector<std::uint16_t> mosaic(static_cast<std::size_t>(w) * h);
  const double range = static_cast<double>(white_level) - black_level;
  ParallelFor(static_cast<std::size_t>(h), [&](std::size_t b, std::size_t e) {
    for (std::size_t r = b; r < e; ++r) {
      for (int c = 0; c < w; ++c) {
        const int colour = CfaColourAt(pattern, static_cast<int>(r), c);
        const double v = black_level + static_cast<double>(rgb.at(colour, static_cast<int>(r), c)) * range;
        const double clamped = std::clamp(std::isfinite(v) ? std::round(v) : 0.0, 0.0, static_cast<double>(white_level));
        mosaic[r * w + c] = static_cast<std::uint16_t>(clamped);
      }
    }
  });
  return mosaic;
}

void WriteDng(const fs::path& path, const std::vector<std::uint16_t>& mosaic, int width, int height,
              const DngWriteOptions& options) {
  if (width < kMinDngSide || height < kMinDngSide || mosaic.size() != static_cast<std::size_t>(width) * height) {
    throw std::invalid_argument("WriteDng: mosaic of " + std::to_string(mosaic.size()) + " values for " +
                                std::to_string(width) + "x" + std::to_string(height));
  }
  if (options.white_level <= options.black_level) throw std::invalid_argument("WriteDng: white_level <= black_level");
  for (double n : options.as_shot_neutral) {
    if (!(n > 0.0 && n <= 1.0)) throw std::invalid_argument("WriteDng: AsShotNeutral values must be in (0, 1]");
  }
  const Eigen::Matrix3d colour_matrix = options.colour_matrix.value_or(LinearSrgbToXyz().inverse());

  // Appended piece by piece: GCC 12 warns (-Wrestrict, a false positive) on "." + s + ".partial".
  std::string temp_name = ".";
  temp_name += path.filename().string();
  temp_name += ".partial";
  fs::path temp = path;
  temp.replace_filename(temp_name);
  auto fail = [&](const std::string& what) {
    std::error_code ignored;
    fs::remove(temp, ignored);
    throw InputError(path.string(), "", what);
  };
  {
    std::unique_ptr<TIFF, TiffCloser> tif(TIFFOpen(temp.c_str(), "w"));
    if (!tif) fail("a writable location for a DNG file");
    TIFF* t = tif.get();
    const std::uint8_t dng_version[4] = {1, 4, 0, 0};
    const std::uint8_t dng_backward[4] = {1, 1, 0, 0};
    const std::uint16_t repeat_dim[2] = {2, 2};
    const auto codes = PatternCodes(options.pattern);
    const std::uint8_t plane_colours[3] = {0, 1, 2};
    const float black = options.black_level;
    const std::uint32_t white = options.white_level;
    float matrix[9];
    for (int i = 0; i < 9; ++i) matrix[i] = static_cast<float>(colour_matrix(i / 3, i % 3));
    const float neutral[3] = {static_cast<float>(options.as_shot_neutral[0]),
                              static_cast<float>(options.as_shot_neutral[1]),
                              static_cast<float>(options.as_shot_neutral[2])};
    bool ok = TIFFSetField(t, TIFFTAG_SUBFILETYPE, 0) && TIFFSetField(t, TIFFTAG_IMAGEWIDTH, width) &&
              TIFFSetField(t, TIFFTAG_IMAGELENGTH, height) && TIFFSetField(t, TIFFTAG_BITSPERSAMPLE, 16) &&
              TIFFSetField(t, TIFFTAG_SAMPLESPERPIXEL, 1) && TIFFSetField(t, TIFFTAG_COMPRESSION, COMPRESSION_NONE) &&
              TIFFSetField(t, TIFFTAG_PHOTOMETRIC, kPhotometricCfa) &&
              TIFFSetField(t, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG) &&
              TIFFSetField(t, TIFFTAG_ORIENTATION, ORIENTATION_TOPLEFT) &&
              TIFFSetField(t, TIFFTAG_ROWSPERSTRIP, kRowsPerStrip) &&
              TIFFSetField(t, TIFFTAG_MAKE, options.camera_model.c_str()) &&
              TIFFSetField(t, TIFFTAG_MODEL, options.camera_model.c_str()) &&
              TIFFSetField(t, TIFFTAG_SOFTWARE, "u3mscan") &&
              TIFFSetField(t, TIFFTAG_DNGVERSION, dng_version) &&
              TIFFSetField(t, TIFFTAG_DNGBACKWARDVERSION, dng_backward) &&
              TIFFSetField(t, TIFFTAG_UNIQUECAMERAMODEL, options.camera_model.c_str()) &&
              TIFFSetField(t, TIFFTAG_CFAREPEATPATTERNDIM, repeat_dim) &&
              TIFFSetField(t, TIFFTAG_CFAPATTERN, 4, codes.data()) &&
              TIFFSetField(t, TIFFTAG_CFAPLANECOLOR, 3, plane_colours) &&
              TIFFSetField(t, TIFFTAG_CFALAYOUT, kCfaLayoutRectangular) &&
              TIFFSetField(t, TIFFTAG_BLACKLEVEL, 1, &black) && TIFFSetField(t, TIFFTAG_WHITELEVEL, 1, &white) &&
              TIFFSetField(t, TIFFTAG_COLORMATRIX1, 9, matrix) &&
              TIFFSetField(t, TIFFTAG_CALIBRATIONILLUMINANT1, kIlluminantD65) &&
              TIFFSetField(t, TIFFTAG_ASSHOTNEUTRAL, 3, neutral);
    if (!ok) fail("a DNG file libtiff can write (setting a tag failed)");
    std::vector<std::uint16_t> row(static_cast<std::size_t>(width));
    for (int r = 0; r < height && ok; ++r) {
      std::copy_n(mosaic.data() + static_cast<std::size_t>(r) * width, width, row.data());
      ok = TIFFWriteScanline(t, row.data(), static_cast<std::uint32_t>(r), 0) == 1;
    }
    if (!ok) fail("a DNG file that can be written completely (disk full?)");
    if (!TIFFFlush(t)) fail("a DNG file that can be written completely (disk full?)");
  }
  std::error_code ec;
  fs::rename(temp, path, ec);
  if (ec) fail("a location the DNG can be renamed into: " + ec.message());
}

}  // namespace u3mscan
