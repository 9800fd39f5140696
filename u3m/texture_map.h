#pragma once
// Texture maps of a scan as U3M files (docs/u3ma-and-textures.md, docs/u3m-conventions.md).
// In memory every map is linear float (core::Image); the map's kind decides the file encoding:
//   colour  basecolor, subsurface_color: linear RGB(A) in memory; 8/16-bit files hold sRGB-encoded
//           values and are tagged sRGB, EXR holds the linear values.
//   data    roughness, metalness, alpha, displacement, ...: values as they are, no colour profile.
//   normal  tangent-space unit vectors, OpenGL convention (+X right = red, +Y up = green, +Z out of
//           the surface = blue); memory holds n in [-1, 1], every file holds (n + 1) / 2.
// Integer files clamp the encoded value to 0..1 and round to the nearest code; the *Mean functions
// below average exactly those quantised values, so a `constant` computed with them equals the mean
// of the texture a reader loads.

#include <array>
#include <ctime>
#include <filesystem>
#include <vector>

#include "core/image.h"
#include "u3m/image_io.h"
#include "u3m/material.h"

namespace u3mscan {

enum class MapKind { kColour, kData, kNormal };

// Physical size of a map as U3M's `image` object needs it.
struct MapGeometry {
  int width_px = 0;
  int height_px = 0;
  double width_mm = 0.0;   // width_px * pitch_x_mm
  double height_mm = 0.0;  // height_px * pitch_y_mm
  double dpi_x = 0.0;      // pixels per inch = 25.4 / pitch_x_mm
  double dpi_y = 0.0;
};

// Throws std::invalid_argument unless the sizes and pitches are positive and finite.
MapGeometry GeometryFromPitch(int width_px, int height_px, double pitch_x_mm, double pitch_y_mm);
// Square pixels of image.pitch_mm().
MapGeometry GeometryOf(const Image& image);

// The U3M `image` object of a texture file at `relative_path` with this geometry (repeat defaults).
TextureImage TextureImageOf(const std::string& relative_path, const MapGeometry& geometry);

// Writes `map` as the file the extension names: .png (kUInt8/kUInt16), .tif/.tiff (kUInt8/kUInt16)
// or .exr (kFloat32). Normal maps need 3 channels, colour maps 3 or 4 (alpha stays linear), data
// maps any count. The pitch goes into the file's resolution tags. Atomic (temp file + rename);
// throws InputError naming the file on a bad combination or I/O failure. Returns the geometry
// (zero mm/dpi when the map has no pitch). `modified_utc` goes into TIFF's DateTime (0 = now):
// pass the package's time for reproducible files.
MapGeometry WriteTextureMap(const Image& map, MapKind kind, const std::filesystem::path& path, SampleFormat format,
                            std::time_t modified_utc = 0);

struct TextureFileInfo {
  ImageReadInfo file;     // size, sample format, sRGB tag, dpi as stored
  MapGeometry geometry;   // from the pixel count and the file's dpi (zero when the file has none)
};

// Reads a map back to linear float: colour maps from integer files are sRGB-decoded (the U3M rule,
// whatever the tag), normal maps are decoded to 2 v - 1. The pitch comes from the file's dpi when
// x and y agree. Throws InputError naming the file.
Image ReadTextureMap(const std::filesystem::path& path, MapKind kind, TextureFileInfo* info = nullptr);

// Per-channel mean of the linear values a reader gets back after the map is written with `format`
// (integer formats: quantised like WriteTextureMap; kFloat32: the values as they are).
std::vector<double> MapChannelMeans(const Image& map, MapKind kind, SampleFormat format);
// U3M's value of a scalar map averaged over the pixels: offset + average(channels) * factor.
double ScalarMapMean(const Image& map, SampleFormat format, double factor = 1.0, double offset = 0.0);
// Linear RGB mean of a colour map times a linear factor (U3M mode "multiply"); needs >= 3 channels.
std::array<double, 3> ColourMapMean(const Image& map, SampleFormat format,
                                    const std::array<double, 3>& factor = {1.0, 1.0, 1.0});
// Mean normal (decoded as a reader does), renormalised to unit length; (0, 0, 1) when the mean is
// degenerate. Needs 3 channels.
std::array<double, 3> NormalMapMean(const Image& map, SampleFormat format);

// The one quantiser shared by the writer and the means: the value a reader gets back from storing
// `value` (linear, or a normal component in [-1, 1]) in an integer file of `format`. Alpha
// (channel 3) of colour maps is linear. kFloat32 returns the value unchanged.
float QuantisedValue(float value, MapKind kind, int channel, SampleFormat format);

}  // namespace u3mscan
