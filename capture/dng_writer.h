#pragma once
// DNG writing: a Bayer CFA mosaic as a DNG 1.4 file that libraw (and any DNG reader) decodes.
// The "writing" half of capture/, used by the synthetic scanner to make RAW frames.
//
// Colour: with the default colour matrix and a neutral AsShotNeutral, the camera's colour space
// IS linear sRGB (ColorMatrix1 = the inverse of libraw's sRGB->XYZ D65 matrix), so the frame
// decoder returns exactly the linear RGB the mosaic was made from (docs/capture-reading.md):
//   decoded_c = (raw - black_level) / (white_level - black_level)   at each photosite of colour c.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "core/image.h"

namespace u3mscan {

// The colours of the 2x2 CFA tile, read row by row: kRggb = R at (0,0), G (0,1), G (1,0), B (1,1).
enum class CfaPattern { kRggb, kBggr, kGrbg, kGbrg };

// 0 = red, 1 = green, 2 = blue for the photosite at (row, col).
int CfaColourAt(CfaPattern pattern, int row, int col);

struct DngWriteOptions {
  CfaPattern pattern = CfaPattern::kRggb;
  std::uint16_t black_level = 0;      // raw ADU of no light
  std::uint16_t white_level = 65535;  // raw ADU of the saturation level (> black_level)
  std::string camera_model = "u3mscan synthetic";  // UniqueCameraModel, also Make/Model
  // ColorMatrix1: XYZ (D65) -> camera RGB, row-major. Absent: camera RGB = linear sRGB.
  std::optional<Eigen::Matrix3d> colour_matrix;
  // AsShotNeutral: the camera's response to white, (1, 1, 1) = no white balance to undo.
  std::array<double, 3> as_shot_neutral{1.0, 1.0, 1.0};
};

// libraw refuses RAW images smaller than 22 pixels a side (it takes them for thumbnails).
inline constexpr int kMinDngSide = 22;

// Writes a 16-bit uncompressed CFA DNG (DNGVersion 1.4, CalibrationIlluminant1 D65). `mosaic`
// holds width*height raw values row-major; width and height >= kMinDngSide. Atomic: a temporary file beside `path`, then rename.
// Throws std::invalid_argument for inconsistent arguments and InputError (naming `path`) when the
// file cannot be written.
void WriteDng(const std::filesystem::path& path, const std::vector<std::uint16_t>& mosaic, int width, int height,
              const DngWriteOptions& options = {});

// The mosaic a sensor with the given levels records for linear RGB `rgb` (3 channels, 1.0 =
// white level): raw = black + v * (white - black), rounded and clamped to [0, white]. No noise.
std::vector<std::uint16_t> MosaicFromLinearRgb(const Image& rgb, CfaPattern pattern, std::uint16_t black_level,
                                               std::uint16_t white_level);

// libraw's sRGB (D65) -> XYZ matrix; its inverse is the default ColorMatrix1.
Eigen::Matrix3d LinearSrgbToXyz();

}  // namespace u3mscan
