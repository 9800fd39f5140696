#include "datasets_synthetic/calibration_frames.h"

#include <algorithm>
#include <cmath>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/core.hpp>
#include <stdexcept>

#include "core/colour.h"
#include "datasets_synthetic/renderer.h"

namespace u3mscan::synthetic {
namespace {

constexpr double kTargetFillOfView = 0.85;  // printed targets cover this much of the view
constexpr double kBoardBlack = 0.04, kBoardWhite = 0.9;
constexpr double kChartBodyAlbedo = 0.03;
constexpr double kMarkerPerSquare = 0.7;
// Camera pixels per board square we aim for (min 3 squares a side): 40 keeps the markers legible
// to the oblique camera, which sees squares foreshortened to half their height (24 did not).
constexpr double kPixelsPerSquare = 40.0;
constexpr int kTargetSamplesPerAxis = 3;  // anti-aliasing of printed edges
constexpr int kSphereSamplesPerAxis = 4;  // the highlight is a few pixels: its centroid must be sub-pixel
// Chart layout in patch sizes: gaps between patches and the black border around them.
constexpr double kChartGap = 0.25, kChartBorder = 0.5;
constexpr int kChartColumns = 6, kChartRows = 4;

cv::aruco::PREDEFINED_DICTIONARY_NAME DictionaryByName(const std::string& name) {
  static const std::pair<const char*, cv::aruco::PREDEFINED_DICTIONARY_NAME> kNames[] = {
      {"DICT_4X4_50", cv::aruco::DICT_4X4_50},   {"DICT_4X4_100", cv::aruco::DICT_4X4_100},
      {"DICT_5X5_50", cv::aruco::DICT_5X5_50},   {"DICT_5X5_100", cv::aruco::DICT_5X5_100},
      {"DICT_5X5_250", cv::aruco::DICT_5X5_250}, {"DICT_6X6_100", cv::aruco::DICT_6X6_100},
      {"DICT_6X6_250", cv::aruco::DICT_6X6_250}};
  for (const auto& [n, id] : kNames) {
    if (name == n) return id;
  }
  throw std::invalid_argument("unknown ArUco dictionary " + name);
}

// View of the top camera on the sample plane, mm.
Eigen::Vector2d ViewSizeMm(const Rig& rig) {
  const RigCamera& cam = rig.cameras.at(0);
  return {cam.width * rig.ground_pitch_mm, cam.height * rig.ground_pitch_mm};
}

PlaneTarget BoardTarget(const Rig& rig, const BoardSpec& board) {
  const double px_per_square = board.square_mm / rig.ground_pitch_mm;
  // Several texels per camera pixel so the texture never limits the edge position.
  const int texels = std::clamp(static_cast<int>(std::ceil(4 * px_per_square)), 16, 400);
  PlaneTarget target;
  target.albedo = DrawBoardTexture(board, texels);
  target.rect_mm[0] = board.origin_mm[0];
  target.rect_mm[1] = board.origin_mm[1] - board.squares_y * board.square_mm;
  target.rect_mm[2] = board.origin_mm[0] + board.squares_x * board.square_mm;
  target.rect_mm[3] = board.origin_mm[1];
  return target;
}

}  // namespace

CalibrationTargets MakeCalibrationTargets(const Rig& rig) {
  CalibrationTargets t;
  const Eigen::Vector2d view = ViewSizeMm(rig);
  const RigCamera& cam = rig.cameras.at(0);
  // Board: as many squares as keep ~40 camera pixels each, 3..12 per side, all inside the view.
  BoardSpec& b = t.board;
  b.squares_x = std::clamp(static_cast<int>(kTargetFillOfView * cam.width / kPixelsPerSquare), 3, 12);
  b.squares_y = std::clamp(static_cast<int>(kTargetFillOfView * cam.height / kPixelsPerSquare), 3, 12);
  b.square_mm = kTargetFillOfView * std::min(view.x() / b.squares_x, view.y() / b.squares_y);
  b.marker_mm = kMarkerPerSquare * b.square_mm;
  b.dictionary = "DICT_5X5_100";  // 100 markers >= 12 x 12 / 2
  b.origin_mm = {-0.5 * b.squares_x * b.square_mm, 0.5 * b.squares_y * b.square_mm};  // top-left corner

  const double short_side = std::min(view.x(), view.y());
  const bool point_lights = std::any_of(rig.lights.begin(), rig.lights.end(),
                                        [](const RigLight& l) { return l.type == RigLightType::kPoint; });
  if (point_lights) {
    // Three placements spread over the view: light positions are triangulated from the rays the
    // highlights give, and the baseline between placements sets how well the distance is known
    // (two placements 0.44 of the view apart left 2-5 % distance errors at 400 mm).
    t.sphere_radius_mm = 0.12 * short_side;
    const double r = t.sphere_radius_mm, dx = 0.32 * view.x();
    t.sphere_centers_mm = {{-dx, -0.22 * view.y(), r}, {dx, -0.22 * view.y(), r}, {0, 0.28 * view.y(), r}};
  } else {
    t.sphere_radius_mm = 0.2 * short_side;
    t.sphere_centers_mm = {{0, 0, t.sphere_radius_mm}};
  }

  const double chart_w = kChartColumns + (kChartColumns - 1) * kChartGap + 2 * kChartBorder;
  const double chart_h = kChartRows + (kChartRows - 1) * kChartGap + 2 * kChartBorder;
  t.chart_patch_mm = kTargetFillOfView * std::min(view.x() / chart_w, view.y() / chart_h);
  t.chart_rect_mm = {-0.5 * chart_w * t.chart_patch_mm, -0.5 * chart_h * t.chart_patch_mm,
                     0.5 * chart_w * t.chart_patch_mm, 0.5 * chart_h * t.chart_patch_mm};
  return t;
}

const std::array<std::array<int, 3>, 24>& ColorCheckerSrgb8() {
  static const std::array<std::array<int, 3>, 24> kPatches = {{
      {115, 82, 68},   {194, 150, 130}, {98, 122, 157},  {87, 108, 67},   {133, 128, 177}, {103, 189, 170},
      {214, 126, 44},  {80, 91, 166},   {193, 90, 99},   {94, 60, 108},   {157, 188, 64},  {224, 163, 46},
      {56, 61, 150},   {70, 148, 73},   {175, 54, 60},   {231, 199, 31},  {187, 86, 149},  {8, 133, 161},
      {243, 243, 242}, {200, 200, 200}, {160, 160, 160}, {122, 122, 121}, {85, 85, 85},    {52, 52, 52},
  }};
  return kPatches;
}

Eigen::Vector3d ColorCheckerLinear(int patch) {
  const auto& s = ColorCheckerSrgb8().at(patch);
  return {SrgbToLinear(s[0] / 255.0), SrgbToLinear(s[1] / 255.0), SrgbToLinear(s[2] / 255.0)};
}

Image DrawBoardTexture(const BoardSpec& board, int texels_per_square) {
  const auto dictionary = cv::aruco::getPredefinedDictionary(DictionaryByName(board.dictionary));
  const auto charuco = cv::aruco::CharucoBoard::create(board.squares_x, board.squares_y,
                                                       static_cast<float>(board.square_mm),
                                                       static_cast<float>(board.marker_mm), dictionary);
  cv::Mat printed;
  charuco->draw(cv::Size(board.squares_x * texels_per_square, board.squares_y * texels_per_square), printed, 0, 1);
  Image tex(printed.cols, printed.rows, 1);
  for (int r = 0; r < printed.rows; ++r) {
    for (int c = 0; c < printed.cols; ++c) {
      tex.at(0, r, c) = static_cast<float>(kBoardBlack + (kBoardWhite - kBoardBlack) * printed.at<unsigned char>(r, c) / 255.0);
    }
  }
  return tex;
}

Image DrawChartTexture(const CalibrationTargets& targets, int texels_per_patch) {
  const int n = texels_per_patch;
  const int gap = static_cast<int>(std::lround(kChartGap * n)), border = static_cast<int>(std::lround(kChartBorder * n));
  const int w = kChartColumns * n + (kChartColumns - 1) * gap + 2 * border;
  const int h = kChartRows * n + (kChartRows - 1) * gap + 2 * border;
  Image tex(w, h, 3, static_cast<float>(kChartBodyAlbedo));
  for (int k = 0; k < kChartColumns * kChartRows; ++k) {
    const Eigen::Vector3d albedo = ColorCheckerLinear(k);
    const int r0 = border + (k / kChartColumns) * (n + gap), c0 = border + (k % kChartColumns) * (n + gap);
    for (int c = 0; c < 3; ++c)
      for (int r = r0; r < r0 + n; ++r)
        for (int q = c0; q < c0 + n; ++q) tex.at(c, r, q) = static_cast<float>(albedo[c]);
  }
  (void)targets;
  return tex;
}

Image RenderDarkFrame(const Rig& rig, int camera_index) {
  const RigCamera& cam = rig.cameras.at(camera_index);
  return Image(cam.width, cam.height, 3, 0.0f);
}

Image RenderFlatFrame(const Rig& rig, int camera_index, const CalibrationTargets& targets, int light_index) {
  PlaneTarget white;
  white.albedo = Image(1, 1, 1, static_cast<float>(targets.white_reflectance));
  // The white target covers the whole view (it is larger than anything the camera sees).
  const double big = 1e4;
  white.rect_mm[0] = white.rect_mm[1] = -big;
  white.rect_mm[2] = white.rect_mm[3] = big;
  return RenderPlaneTarget(rig, camera_index, white, &rig.lights.at(light_index), false, 1);
}

Image RenderBoardFrame(const Rig& rig, int camera_index, const CalibrationTargets& targets, int light_index) {
  return RenderPlaneTarget(rig, camera_index, BoardTarget(rig, targets.board), &rig.lights.at(light_index), false,
                           kTargetSamplesPerAxis);
}

Image RenderSphereFrame(const Rig& rig, int camera_index, const CalibrationTargets& targets, int light_index,
                        int placement) {
  return RenderMirrorSphere(rig, camera_index, rig.lights.at(light_index), targets.sphere_centers_mm.at(placement),
                            targets.sphere_radius_mm, targets.sphere_highlight_level, kSphereSamplesPerAxis);
}

Image RenderChartFrame(const Rig& rig, int camera_index, const CalibrationTargets& targets, int light_index) {
  PlaneTarget chart;
  const double px_per_patch = targets.chart_patch_mm / rig.ground_pitch_mm;
  chart.albedo = DrawChartTexture(targets, std::clamp(static_cast<int>(std::ceil(4 * px_per_patch)), 16, 400));
  for (int k = 0; k < 4; ++k) chart.rect_mm[k] = targets.chart_rect_mm[k];
  return RenderPlaneTarget(rig, camera_index, chart, &rig.lights.at(light_index), false, kTargetSamplesPerAxis);
}

}  // namespace u3mscan::synthetic
