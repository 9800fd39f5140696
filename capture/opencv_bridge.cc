#include "capture/opencv_bridge.h"

#include <algorithm>

#include "core/colour.h"

namespace u3mscan::internal {

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
