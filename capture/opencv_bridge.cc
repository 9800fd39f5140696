#include "capture/opencv_bridge.h"

#include <algorithm>
#include <vector>

#include "core/colour.h"

namespace u3mscan::internal {

double Quantile(const cv::Mat& grey, double q) {
  const std::size_t total = grey.total();
  if (total == 0) return 0.0;
  const std::size_t stride = std::max<std::size_t>(1, total / (1u << 20));
  std::vector<float> values;
  values.reserve(total / stride + 1);
  for (int r = 0; r < grey.rows; ++r) {
    const float* row = grey.ptr<float>(r);
    for (int c = 0; c < grey.cols; ++c) {
      if ((static_cast<std::size_t>(r) * grey.cols + c) % stride == 0) values.push_back(row[c]);
    }
  }
  const std::size_t k = std::min(values.size() - 1, static_cast<std::size_t>(q * (values.size() - 1)));
  std::nth_element(values.begin(), values.begin() + k, values.end());
  return values[k];
}

cv::Mat ToDisplay8(const cv::Mat& grey_linear, double white) {
  cv::Mat out(grey_linear.rows, grey_linear.cols, CV_8U);
  const double scale = white > 0.0 ? 1.0 / white : 1.0;
  // 4096-entry table of the sRGB curve: the detectors need no more than 8 bits out.
  static const std::vector<unsigned char> kTable = [] {
    std::vector<unsigned char> table(4097);
    for (int i = 0; i <= 4096; ++i) {
      table[i] = static_cast<unsigned char>(std::lround(255.0 * LinearToSrgb(i / 4096.0)));
    }
    return table;
  }();
  for (int r = 0; r < grey_linear.rows; ++r) {
    const float* in = grey_linear.ptr<float>(r);
    unsigned char* o = out.ptr<unsigned char>(r);
    for (int c = 0; c < grey_linear.cols; ++c) {
      const double v = std::clamp(in[c] * scale, 0.0, 1.0);
      o[c] = kTable[static_cast<int>(v * 4096.0 + 0.5)];
    }
  }
  return out;
}

}  // namespace u3mscan::internal
