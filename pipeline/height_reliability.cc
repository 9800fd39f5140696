#include "pipeline/height_reliability.h"

#include <cstdio>

namespace u3mscan {

std::string HeightUnreliableReason(const reconstruction::PhotometricStereoResult& photometric_stereo,
                                   const HeightReliabilityOptions& options) {
  const Image& confidence = photometric_stereo.confidence;
  if (confidence.empty()) return "no photometric-stereo confidence: the height cannot be checked";
  const double pixels = static_cast<double>(confidence.pixel_count());
  const double regularised_share = static_cast<double>(photometric_stereo.regularised_pixels) / pixels;
  const double mean_confidence = confidence.ChannelMean(0);
  char buffer[320];
  if (regularised_share > options.max_regularised_share) {
    std::snprintf(buffer, sizeof buffer,
                  "photometric stereo guessed the slope of %.0f %% of the pixels (normal regularised toward its "
                  "neighbours: too few usable lights or an ill-conditioned light system; > %.0f %%), mean confidence "
                  "%.2f: the height range may be off by a factor",
                  100.0 * regularised_share, 100.0 * options.max_regularised_share, mean_confidence);
    return buffer;
  }
  if (mean_confidence < options.min_mean_confidence) {
    std::snprintf(buffer, sizeof buffer,
                  "mean photometric-stereo confidence %.2f < %.2f: the normals, and the height integrated from them, "
                  "may be off by a factor",
                  mean_confidence, options.min_mean_confidence);
    return buffer;
  }
  return "";
}

}  // namespace u3mscan
