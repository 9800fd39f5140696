#include "core/image.h"

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <string>

namespace u3mscan {

Image::Image(int width, int height, int channels, float fill, double pitch_mm)
    : width_(width), height_(height), channels_(channels), pitch_mm_(pitch_mm) {
  if (width < 0 || height < 0 || channels < 0) {
    throw std::invalid_argument("Image: negative size " + std::to_string(width) + "x" +
                                std::to_string(height) + "x" + std::to_string(channels));
  }
  // Guard against size_t overflow before allocating: a hostile header must not wrap around.
  const std::size_t max_values = std::numeric_limits<std::size_t>::max() / sizeof(float);
  const std::size_t plane = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  if (channels != 0 && plane > max_values / static_cast<std::size_t>(channels)) {
    throw std::length_error("Image: size overflows memory");
  }
  data_.assign(plane * static_cast<std::size_t>(channels), fill);
}

std::span<float> Image::plane(int channel) {
  return {data_.data() + static_cast<std::size_t>(channel) * pixel_count(), pixel_count()};
}

std::span<const float> Image::plane(int channel) const {
  return {data_.data() + static_cast<std::size_t>(channel) * pixel_count(), pixel_count()};
}

double Image::ChannelMean(int channel) const {
  if (pixel_count() == 0) return 0.0;
  double sum = 0.0;
  for (float v : plane(channel)) sum += v;
  return sum / static_cast<double>(pixel_count());
}

Image CropRows(const Image& image, int row0, int rows) {
  if (row0 < 0 || rows < 0 || row0 + rows > image.height()) throw std::out_of_range("CropRows: rows outside the image");
  Image out(image.width(), rows, image.channels(), 0.0f, image.pitch_mm());
  const std::size_t w = static_cast<std::size_t>(image.width());
  for (int c = 0; c < image.channels(); ++c) {
    const float* src = image.plane(c).data() + static_cast<std::size_t>(row0) * w;
    std::copy(src, src + static_cast<std::size_t>(rows) * w, out.data().data() + static_cast<std::size_t>(c) * rows * w);
  }
  return out;
}

void PasteRows(const Image& band, int row0, Image* full) {
  if (band.width() != full->width() || band.channels() != full->channels() || row0 < 0 ||
      row0 + band.height() > full->height()) {
    throw std::out_of_range("PasteRows: band does not fit the image");
  }
  const std::size_t w = static_cast<std::size_t>(band.width());
  for (int c = 0; c < band.channels(); ++c) {
    const float* src = band.plane(c).data();
    std::copy(src, src + static_cast<std::size_t>(band.height()) * w,
              full->data().data() + (static_cast<std::size_t>(c) * full->height() + row0) * w);
  }
}

}  // namespace u3mscan
