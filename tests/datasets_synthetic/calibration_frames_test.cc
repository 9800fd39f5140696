#include "datasets_synthetic/calibration_frames.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "datasets_synthetic/rig.h"

namespace u3mscan::synthetic {
namespace {

// Detected ChArUco corners against the projection of the board's object points through the true
// camera: the rendering must put the board where BoardSpec says, to a small fraction of a pixel.
// The spread is the 8-bit corner detector's (cornerSubPix on a 7x7 window next to marker edges).
// A systematic offset would be the renderer's: the mean must be far below the spread.
constexpr double kBoardCornerBiasTolerancePx = 0.06;
constexpr double kBoardCornerRmsTolerancePx = 0.15;
constexpr double kBoardCornerWorstTolerancePx = 0.3;
constexpr int kBoardWidth = 480, kBoardHeight = 360;

cv::Mat ToGray8(const Image& linear) {
  double peak = 0;
  for (float v : linear.plane(1)) peak = std::max(peak, static_cast<double>(v));
  cv::Mat gray(linear.height(), linear.width(), CV_8UC1);
  for (int r = 0; r < linear.height(); ++r)
    for (int c = 0; c < linear.width(); ++c)
      gray.at<unsigned char>(r, c) = cv::saturate_cast<unsigned char>(255.0 * linear.at(1, r, c) / peak);
  return gray;
}

void ExpectBoardCornersWhereSpecSays(const std::string& rig_name, int camera_index) {
  RigOptions options;
  options.width = kBoardWidth;
  options.height = kBoardHeight;
  const Rig rig = MakeRig(rig_name, options);
  const CalibrationTargets targets = MakeCalibrationTargets(rig);
  const Image frame = RenderBoardFrame(rig, camera_index, targets, 0);
  const BoardSpec& b = targets.board;
  const auto dictionary = cv::aruco::getPredefinedDictionary(cv::aruco::DICT_5X5_100);
  const auto board = cv::aruco::CharucoBoard::create(b.squares_x, b.squares_y, static_cast<float>(b.square_mm),
                                                     static_cast<float>(b.marker_mm), dictionary);
  const cv::Mat gray = ToGray8(frame);
  std::vector<std::vector<cv::Point2f>> marker_corners;
  std::vector<int> marker_ids;
  cv::aruco::detectMarkers(gray, dictionary, marker_corners, marker_ids);
  ASSERT_GE(marker_ids.size(), 4u) << rig_name;
  std::vector<cv::Point2f> corners;
  std::vector<int> ids;
  cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, gray, board, corners, ids);
  ASSERT_GE(ids.size(), 6u) << rig_name;
  // OpenCV 4.6's interpolateCornersCharuco returns corners 0.5 px down and right of OpenCV's own
  // pixel-centre convention (measured on a drawn board: a corner between pixels 59 and 60 comes
  // back at 60.0); a plain cornerSubPix pass lands on 59.5. Refine so the test checks the render.
  cv::cornerSubPix(gray, corners, cv::Size(3, 3), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-4));
  const RigCamera& cam = rig.cameras[camera_index];
  double worst = 0, sum2 = 0, mx = 0, my = 0;
  for (std::size_t k = 0; k < ids.size(); ++k) {
    const cv::Point3f obj = board->chessboardCorners[ids[k]];
    const Eigen::Vector3d world(b.origin_mm[0] + obj.x, b.origin_mm[1] - obj.y, 0.0);
    Eigen::Vector2d px;
    ASSERT_TRUE(ProjectToPixel(cam, world, &px));
    worst = std::max(worst, std::hypot(px.x() - corners[k].x, px.y() - corners[k].y));
    sum2 += std::pow(px.x() - corners[k].x, 2) + std::pow(px.y() - corners[k].y, 2);
    mx += px.x() - corners[k].x; my += px.y() - corners[k].y;
  }
  EXPECT_LT(std::sqrt(sum2 / ids.size()), kBoardCornerRmsTolerancePx) << rig_name << " camera " << camera_index;
  EXPECT_LT(std::hypot(mx, my) / ids.size(), kBoardCornerBiasTolerancePx) << rig_name << " camera " << camera_index;
  EXPECT_LT(worst, kBoardCornerWorstTolerancePx) << rig_name << " camera " << camera_index;
}

TEST(CalibrationFramesTest, BoardCornersProjectWhereTheSpecSaysTopCamera) { ExpectBoardCornersWhereSpecSays("near", 0); }

TEST(CalibrationFramesTest, BoardCornersProjectWhereTheSpecSaysObliqueCamera) {
  ExpectBoardCornersWhereSpecSays("oblique", 1);
}

// The mirrored emitter's centroid obeys the law of reflection, checked from the image alone:
// back-project the centroid, hit the sphere, reflect the viewing ray; it must point at the light.
void ExpectSphereHighlightWhereReflectionSays(const std::string& rig_name, int light_index, int placement) {
  // Measured 0.01-0.03 deg; a 0.1 px centroid error would turn the reflected ray by ~0.1 deg here
  // (sphere radius ~50 px).
  constexpr double kReflectedAngleToleranceDeg = 0.1;
  RigOptions options;
  options.width = options.height = 480;
  const Rig rig = MakeRig(rig_name, options);
  const CalibrationTargets targets = MakeCalibrationTargets(rig);
  const Image frame = RenderSphereFrame(rig, 0, targets, light_index, placement);
  const RigCamera& cam = rig.cameras[0];
  const RigLight& light = rig.lights[light_index];
  const Eigen::Vector3d c = targets.sphere_centers_mm[placement];
  const double radius = targets.sphere_radius_mm;
  // Centroid of the spot inside the sphere's image (which mirrors only a dark room), cut at 5 % of
  // its peak: a higher cut biases the centroid of a 1-pixel Gaussian by up to 0.1 px.
  Eigen::Vector2d centre_px;
  ASSERT_TRUE(ProjectToPixel(cam, c, &centre_px));
  const double radius_px = radius * cam.fx / (cam.position_mm - c).norm();
  const double threshold = 0.05 * targets.sphere_highlight_level;
  double sw = 0, sx = 0, sy = 0;
  for (int r = 0; r < frame.height(); ++r)
    for (int col = 0; col < frame.width(); ++col) {
      const double v = frame.at(1, r, col);
      if (std::hypot(col - centre_px.x(), r - centre_px.y()) < 0.95 * radius_px && v > threshold) {
        sw += v;
        sx += v * col;
        sy += v * r;
      }
    }
  ASSERT_GT(sw, 0) << rig_name;
  const Eigen::Vector3d d = PixelRayInWorld(cam, sx / sw, sy / sw);
  const Eigen::Vector3d oc = cam.position_mm - c;
  const double b = oc.dot(d), disc = b * b - (oc.squaredNorm() - radius * radius);
  ASSERT_GT(disc, 0) << "the centroid's ray misses the sphere";
  const Eigen::Vector3d p = cam.position_mm + (-b - std::sqrt(disc)) * d;
  const Eigen::Vector3d n = (p - c) / radius;
  const Eigen::Vector3d reflected = d - 2 * d.dot(n) * n;
  const Eigen::Vector3d to_light =
      light.type == RigLightType::kDirectional ? light.direction : Eigen::Vector3d((light.position_mm - p).normalized());
  const double angle_deg = std::acos(std::min(1.0, reflected.dot(to_light))) * 180.0 / M_PI;
  EXPECT_LT(angle_deg, kReflectedAngleToleranceDeg) << rig_name << " light " << light_index << " placement " << placement;
}

TEST(CalibrationFramesTest, SphereHighlightFollowsTheLawOfReflectionDirectional) {
  ExpectSphereHighlightWhereReflectionSays("distant", 3, 0);
}

TEST(CalibrationFramesTest, SphereHighlightFollowsTheLawOfReflectionPointLightEveryPlacement) {
  ExpectSphereHighlightWhereReflectionSays("near", 9, 0);
  ExpectSphereHighlightWhereReflectionSays("near", 9, 1);
  ExpectSphereHighlightWhereReflectionSays("near", 9, 2);
}

// Chart patches are Lambertian with the published colours: under one light, patch ratios are
// albedo ratios (irradiance and vignetting barely change over one patch's centre).
TEST(CalibrationFramesTest, ChartPatchesCarryThePublishedColours) {
  constexpr double kRatioTolerance = 0.01;
  RigOptions options;
  options.width = 240;
  options.height = 180;
  const Rig rig = MakeRig("distant", options);
  const CalibrationTargets targets = MakeCalibrationTargets(rig);
  const Image frame = RenderChartFrame(rig, 0, targets, 0);
  const RigCamera& cam = rig.cameras[0];
  const double s = targets.chart_patch_mm, step = s * 1.25;
  auto patch_value = [&](int k, int channel) {
    const double x = targets.chart_rect_mm[0] + 0.5 * s + (k % 6) * step + 0.5 * s;
    const double y = targets.chart_rect_mm[3] - 0.5 * s - (k / 6) * step - 0.5 * s;
    Eigen::Vector2d px;
    EXPECT_TRUE(ProjectToPixel(cam, Eigen::Vector3d(x, y, 0), &px));
    return static_cast<double>(frame.at(channel, static_cast<int>(std::lround(px.y())), static_cast<int>(std::lround(px.x()))));
  };
  const RigLight& light = rig.lights[0];
  for (int k : {0, 6, 14, 22}) {
    for (int ch = 0; ch < 3; ++ch) {
      const double ratio = patch_value(k, ch) / patch_value(18, ch);
      EXPECT_NEAR(ratio, ColorCheckerLinear(k)[ch] / ColorCheckerLinear(18)[ch], kRatioTolerance) << k << " " << ch;
    }
  }
  (void)light;
}

}  // namespace
}  // namespace u3mscan::synthetic
