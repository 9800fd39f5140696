#pragma once
// Light calibration from mirror-sphere frames: the sphere is located (from the manifest's
// centre_mm, or found in the frame: a Hough circle refined to sub-pixel edges and fitted in 3D as
// the cone of rays tangent to a sphere of the known radius), its specular highlight is found to
// sub-pixel precision, and the view ray is reflected about the sphere's normal there. A distant
// light's direction is the mean of the reflected rays over placements; a point light lies where
// the reflected rays of two or more placements meet (least squares); with one placement it lies on
// that placement's ray, at the distance its flat frame gives (light_from_plane.h, wired in calibrate.cc).

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "capture/camera_model.h"
#include "capture/light_from_plane.h"
#include "capture/manifest.h"
#include "core/image.h"
#include "core/stack.h"

namespace u3mscan {

struct SphereObservation {
  std::string frame_file;
  Eigen::Vector3d centre_in_world_mm = Eigen::Vector3d::Zero();
  double radius_mm = 0.0;
  bool centre_found_in_frame = false;     // false: the manifest's centre_mm was used
  double edge_residual_px = 0.0;          // RMS of the sub-pixel rim against the fitted sphere
  Eigen::Vector2d highlight_px = Eigen::Vector2d::Zero();
  Eigen::Vector3d highlight_point_in_world_mm = Eigen::Vector3d::Zero();  // on the sphere
  Eigen::Vector3d reflected_in_world = Eigen::Vector3d::UnitZ();          // unit, toward the light
  double apparent_radius_px = 0.0;  // the sphere's radius in the image
  int highlight_area_px = 0;        // pixels of the highlight blob
  Eigen::Vector3d camera_centre_in_world_mm = Eigen::Vector3d::Zero();  // the view ray's origin
};

struct LightFitOptions {
  // How well a highlight is located (px, 1 sigma), for a highlight of one pixel: one smaller than
  // a pixel cannot be placed better than about 0.3 px (uniform within the pixel). A blob of N
  // pixels is located sqrt(N) times better. The angular uncertainty of the reflected ray is
  // 2 * sigma / apparent_radius_px.
  double highlight_sigma_px = 0.3;
  // The manifest's point-light position as a prior (mm, 1 sigma); 0 = no prior. Two placements
  // close together fix a light's direction well and its distance poorly: the prior keeps the
  // distance where the spheres cannot tell.
  double manifest_position_sigma_mm = 10.0;
  // Joint fit (light_joint_fit.h): how far (1 sigma, fraction of the sphere's radius) a placement's
  // centre may move from the mean of its frames' rim fits. Loose on purpose: the rim fits agree
  // with each other to ~0.002 mm but share a bias of 0.003-0.004 mm on the synthetic near rig (a
  // 7.2 mm sphere), 0.06 deg of normal; the highlights of many lights fix the centre better
  // (measured: docs/calibration.md, "Joint fit"). The prior still decides what the highlights
  // cannot (one placement of distant lights: a shift of the centre and a turn of every direction
  // look the same).
  double centre_prior_sigma_of_radius = 0.05;
  // A point light seen on ONE sphere placement: its distance along the sphere's reflected ray from
  // the shading of its flat frame (white target on the sample plane, light_from_plane.h), when
  // the capture has one; otherwise (or when that fit is ill-conditioned) the manifest's distance.
  bool distance_from_flat = true;
  PlaneLightFitOptions plane;
};

// Locates the sphere and its highlight in a linear frame of `camera` (pose known). `known_centre`
// (the manifest's centre_mm) skips the sphere search; `centre_height_mm` (z of the centre, e.g.
// the radius for a sphere resting on the sample plane) lets the search fit x and y only. Throws
// InputError naming `frame_file` when the sphere or the highlight is not found. `refine_highlight`
// false keeps the thresholded blob's centroid (for measurements; see the .cc).
SphereObservation ObserveSphere(const Image& frame_rgb, const CameraModel& camera, const SphereTarget& sphere,
                                const std::string& frame_file,
                                const std::optional<Eigen::Vector3d>& known_centre,
                                const std::optional<double>& centre_height_mm = std::nullopt,
                                bool refine_highlight = true);

struct LightFit {
  LightModel model;
  int placements = 0;
  // Distant: RMS angle (deg) between the placements' directions and the fit. Point: RMS distance
  // (mm) of the fitted position from the placements' reflected rays. 0 with one placement.
  double residual = 0.0;
  std::string residual_unit;  // "deg" or "mm"
  std::string note;           // e.g. "one placement: distance along the ray from the manifest"
  double position_sigma_mm = 0.0;  // point lights: 1-sigma uncertainty along the worst direction
};

// `start` carries the id, type, intensity and profile (from the manifest); its direction or
// position is replaced. Needs at least one observation.
LightFit FitDirectionalLight(const std::vector<SphereObservation>& observations, const LightModel& start);
// The weighted least-squares meeting point of the reflected rays (each weighted by its angular
// uncertainty times the distance), with the manifest's position (start.position_in_world_mm) as a
// prior of options.manifest_position_sigma_mm. One placement and no prior: the point of the ray
// nearest to the manifest's position.
LightFit FitPointLight(const std::vector<SphereObservation>& observations, const LightModel& start,
                       const LightFitOptions& options = {});

}  // namespace u3mscan
