#pragma once
// Image: planar float32 raster with a metric pixel pitch. The one image type every stage passes.

#include <cstddef>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <vector>

namespace u3mscan {

// Planar (channel after channel) float32 image. Row 0 is the top row; columns grow to the right.
// `pitch_mm` is the physical size of one pixel on the sample plane (0 when not metric, e.g. a
// raw camera frame). Planar storage lets a stage touch one channel without striding over others
// and lets per-pixel loops vectorise.
class Image {
 public:
  Image() = default;
  Image(int width, int height, int channels, float fill = 0.0f, double pitch_mm = 0.0);

  int width() const { return width_; }
  int height() const { return height_; }
  int channels() const { return channels_; }
  std::size_t pixel_count() const { return static_cast<std::size_t>(width_) * height_; }
  bool empty() const { return data_.empty(); }

  // Physical pixel size on the sample plane, millimetres (0 = unknown / not metric).
  double pitch_mm() const { return pitch_mm_; }
  void set_pitch_mm(double pitch_mm) { pitch_mm_ = pitch_mm; }

  float& at(int channel, int row, int col) { return data_[index(channel, row, col)]; }
  float at(int channel, int row, int col) const { return data_[index(channel, row, col)]; }

  // One channel as a contiguous row-major plane of width*height values.
  std::span<float> plane(int channel);
  std::span<const float> plane(int channel) const;

  std::vector<float>& data() { return data_; }
  const std::vector<float>& data() const { return data_; }

  // Mean of one channel over all pixels (double accumulation).
  double ChannelMean(int channel) const;

 private:
  std::size_t index(int channel, int row, int col) const {
    return (static_cast<std::size_t>(channel) * height_ + row) * width_ + col;
  }

  int width_ = 0;
  int height_ = 0;
  int channels_ = 0;
  double pitch_mm_ = 0.0;
  std::vector<float> data_;
};

// Rows [row0, row0 + rows) of every channel of an image (a band of a tiled run). Throws
// std::out_of_range when the rows lie outside the image.
Image CropRows(const Image& image, int row0, int rows);
// Writes `band` (same width and channels) into rows [row0, row0 + band height) of `full`. Throws
// std::out_of_range when it does not fit.
void PasteRows(const Image& band, int row0, Image* full);

}  // namespace u3mscan
