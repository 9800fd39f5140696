#pragma once
// Internal helpers for the calibration steps: zero-copy cv::Mat views of Image planes, and
// conversions between the 3-channel planar Image and OpenCV's interleaved BGR layout.

#include <opencv2/core.hpp>

#include "core/image.h"

namespace u3mscan::internal {

// A CV_32F view of one plane; valid as long as `image` is not resized.
inline cv::Mat PlaneView(Image& image, int channel) {
  return cv::Mat(image.height(), image.width(), CV_32F, image.plane(channel).data());
}
inline cv::Mat PlaneView(const Image& image, int channel) {
  return cv::Mat(image.height(), image.width(), CV_32F,
                 const_cast<float*>(image.plane(channel).data()));
}

// Mean of the channels as one CV_32F image (a copy).
inline cv::Mat GreyCopy(const Image& image) {
  cv::Mat grey = cv::Mat::zeros(image.height(), image.width(), CV_32F);
  for (int c = 0; c < image.channels(); ++c) grey += PlaneView(image, c);
  if (image.channels() > 0) grey /= static_cast<double>(image.channels());
  return grey;
}

// The q-quantile (0..1) of a CV_32F image, from at most about a million evenly spread pixels (a
// display stretch needs no more, and a 36-megapixel frame is not sorted).
double Quantile(const cv::Mat& grey, double q);

// Grey 8-bit image for the detectors (aruco, mcc, Hough): the linear value is sRGB-encoded and
// stretched so that `white` maps to 255, as a photograph would be shown.
cv::Mat ToDisplay8(const cv::Mat& grey_linear, double white);

}  // namespace u3mscan::internal
