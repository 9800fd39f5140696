#pragma once
// Rigs of the synthetic scanner: where the cameras and lights are, what the lens and sensor do.
// A rig is everything a physical scanner would put into capture.json (and a little more that only
// the truth knows: vignetting, noise, ambient light).
//
// World frame (docs/capture-format.md): the sample lies in z = 0, +z toward the camera, +x right,
// +y up; lengths in mm. Cameras follow OpenCV: +z looks forward, +x right, +y down in the image;
// pixel centres are integer coordinates. Poses are world_from_camera.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace u3mscan::synthetic {

enum class VignettingModel {
  kNone,
  kCos4,        // cos^4 of the angle between the pixel's ray and the optical axis
  kPolynomial,  // 1 + a1 r^2 + a2 r^4, r = distance to (cx, cy) over the image half-diagonal
};

struct RigCamera {
  std::string id;
  int width = 0;
  int height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;  // pixels
  std::array<double, 5> distortion{};     // OpenCV k1, k2, p1, p2, k3 on normalised coordinates
  Eigen::Matrix3d world_from_camera = Eigen::Matrix3d::Identity();
  Eigen::Vector3d position_mm = Eigen::Vector3d::Zero();  // camera centre in world
  VignettingModel vignetting = VignettingModel::kNone;
  std::array<double, 2> vignetting_poly{};  // a1, a2 of kPolynomial
};

enum class RigLightType { kPoint, kDirectional };

struct RigLight {
  std::string id;
  RigLightType type = RigLightType::kDirectional;
  Eigen::Vector3d position_mm = Eigen::Vector3d::Zero();  // point lights
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();   // directional: unit, sample -> light
  // Contract units (docs/capture-format.md): radiant intensity (point, value * mm^2) or irradiance
  // (directional), already carrying the camera gain, so that a white Lambertian plane facing a
  // directional light of intensity 1 decodes to exposure_s / pi.
  Eigen::Vector3d intensity_rgb = Eigen::Vector3d::Ones();
  // Emitter profile of point lights: intensity * cos^exponent(angle to axis); exponent 0 = isotropic.
  Eigen::Vector3d profile_axis = -Eigen::Vector3d::UnitZ();  // unit, light -> scene
  double profile_exponent = 0.0;
  // Emitter size, only seen in mirror-sphere frames: radius in mm (point) or angular radius in
  // degrees (directional).
  double emitter_radius = 0.0;
};

// Sensor: a linear ADC. Decoded value v = (DN - black) / (white - black); full scale (v = 1)
// collects full_well_e electrons.
struct SensorSpec {
  int bit_depth = 14;
  double black_level_dn = 512.0;
  double white_level_dn = 16383.0;
  double full_well_e = 20000.0;   // electrons at v = 1 (sets the photon shot noise)
  double read_noise_e = 3.0;      // Gaussian, electrons rms
  double fixed_pattern_dn = 1.5;  // per-pixel dark offset (rms DN), the same in every frame of a camera
  // false: no shot, read or fixed-pattern noise, only the rounding to DN (the expected frame): the
  // same capture as with noise, to measure what the noise costs (`u3mscan synth --no-noise`).
  bool noise = true;
};

struct Rig {
  std::string name;
  std::vector<RigCamera> cameras;  // cameras[0] looks straight down on the sample
  std::vector<RigLight> lights;
  SensorSpec sensor;
  double exposure_s = 1.0 / 30.0;          // every sample, flat and calibration frame
  double ambient_irradiance = 0.0;         // room light (contract units), seen in every front frame
  double table_reflectance = 0.18;         // Lambertian table around and under the sample
  double ground_pitch_mm = 25.4 / 300.0;   // cameras[0]'s pixel footprint at the sample centre
  std::uint64_t seed = 1;
};

struct RigOptions {
  int width = 64;   // pixels of every camera
  int height = 64;
  double pitch_mm = 25.4 / 300.0;  // footprint of one pixel of the top camera at the sample centre
  std::uint64_t seed = 1;
  // Number of lights; 0 = the preset's own count (16 on distant/near/oblique/noisy, 12 on grazing and
  // coplanar, 8 on single_light). Ring rigs share the lights over their rings (the first rings take the
  // remainder); grazing and coplanar space them evenly along their circle; single_light has 8 aims only.
  int lights = 0;
  bool Check() const { return width >= 8 && height >= 8 && pitch_mm > 0 && lights >= 0; }
};

// distant, near, oblique, and the extreme presets grazing, coplanar, single_light, noisy.
std::vector<std::string> RigNames();
// Deterministic from options.seed. Throws std::invalid_argument for an unknown name.
Rig MakeRig(const std::string& name, const RigOptions& options);

// Pinhole + OpenCV distortion. Pixel (u, v) -> unit ray direction in world (from the camera centre).
Eigen::Vector3d PixelRayInWorld(const RigCamera& camera, double u, double v);
// World point -> pixel (distorted); returns false behind the camera.
bool ProjectToPixel(const RigCamera& camera, const Eigen::Vector3d& point_in_world, Eigen::Vector2d* pixel);
// Undistorted normalised coordinates (x/z, y/z) of pixel (u, v): inverts the distortion by
// Newton iterations to 1e-12.
Eigen::Vector2d UndistortPixel(const RigCamera& camera, double u, double v);
// Relative illumination of the lens at pixel (u, v), 1 on the axis.
double Vignetting(const RigCamera& camera, double u, double v);

// Irradiance a light gives a point in contract units (E = intensity * profile / d^2 for a point,
// intensity for a directional light), and the unit direction from the point toward the light.
Eigen::Vector3d LightIrradiance(const RigLight& light, const Eigen::Vector3d& point_mm,
                                Eigen::Vector3d* direction_to_light);

}  // namespace u3mscan::synthetic
