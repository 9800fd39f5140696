#pragma once
// Sensor model of the synthetic scanner: turns the renderer's linear values (decoded units: 1 =
// full scale, see renderer.h) into the digital numbers a camera would store, deterministically.
//
// Per pixel: electrons = v * full_well_e, photon shot noise (Gaussian approximation of Poisson,
// variance = mean electrons), read noise (Gaussian, read_noise_e), a fixed-pattern dark offset per
// pixel (the same in every frame of one camera), gain to DN between black and white level,
// rounding, and clipping to [0, white_level] (a pixel that reaches white is saturated).
// Every pixel's noise is a hash of (frame seed, pixel index), so a frame is the same whatever the
// order of rendering or the number of threads.

#include <cstdint>
#include <string_view>
#include <vector>

#include "core/image.h"
#include "datasets_synthetic/rig.h"

namespace u3mscan::synthetic {

// Digital numbers of one frame. channels == 1: an RGGB Bayer mosaic (row 0: R G R G ..., row 1:
// G B G B ...); channels == 3: one value per colour (planar, like Image).
struct RawFrame {
  int width = 0;
  int height = 0;
  int channels = 0;
  std::vector<std::uint16_t> dn;
};

// Colour sampled by mosaic pixel (row, col) of an RGGB pattern: 0 = R, 1 = G, 2 = B.
inline int BayerChannel(int row, int col) { return (row & 1) + (col & 1); }

// Seed of one frame's noise stream: the rig's seed and a name unique to the frame (its path).
std::uint64_t FrameSeed(std::uint64_t rig_seed, std::string_view frame_name);

// `linear` has 1 or 3 channels (1 is taken as grey). bayer: sample the mosaic, else keep 3 channels.
RawFrame ExposeSensor(const Image& linear, const SensorSpec& sensor, std::uint64_t camera_seed,
                      std::uint64_t frame_seed, bool bayer);

// The decoder's view of a raw frame: (DN - black) / (white - black), clipped below at 0, same
// channel layout (a mosaic stays one channel).
Image RawToLinear(const RawFrame& raw, const SensorSpec& sensor);

// Standard deviation (decoded units) of the sensor's noise at linear level v: shot, read, fixed
// pattern and quantisation together (quantisation alone without `noise`). Tests use it to set
// tolerances.
double NoiseSigma(const SensorSpec& sensor, double v);

}  // namespace u3mscan::synthetic
