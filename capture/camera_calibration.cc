#include "capture/camera_calibration.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/core/eigen.hpp>

#include "capture/opencv_bridge.h"
#include "core/error.h"

namespace u3mscan {
namespace {

cv::Ptr<cv::aruco::Dictionary> DictionaryByName(const std::string& name, const std::string& frame_file) {
  static const std::map<std::string, int> kDictionaries = {
      {"DICT_4X4_50", cv::aruco::DICT_4X4_50},     {"DICT_4X4_100", cv::aruco::DICT_4X4_100},
      {"DICT_4X4_250", cv::aruco::DICT_4X4_250},   {"DICT_4X4_1000", cv::aruco::DICT_4X4_1000},
      {"DICT_5X5_50", cv::aruco::DICT_5X5_50},     {"DICT_5X5_100", cv::aruco::DICT_5X5_100},
      {"DICT_5X5_250", cv::aruco::DICT_5X5_250},   {"DICT_5X5_1000", cv::aruco::DICT_5X5_1000},
      {"DICT_6X6_50", cv::aruco::DICT_6X6_50},     {"DICT_6X6_100", cv::aruco::DICT_6X6_100},
      {"DICT_6X6_250", cv::aruco::DICT_6X6_250},   {"DICT_6X6_1000", cv::aruco::DICT_6X6_1000},
      {"DICT_7X7_50", cv::aruco::DICT_7X7_50},     {"DICT_7X7_100", cv::aruco::DICT_7X7_100},
      {"DICT_7X7_250", cv::aruco::DICT_7X7_250},   {"DICT_7X7_1000", cv::aruco::DICT_7X7_1000},
      {"DICT_ARUCO_ORIGINAL", cv::aruco::DICT_ARUCO_ORIGINAL}};
  const auto it = kDictionaries.find(name);
  if (it == kDictionaries.end()) {
    throw InputError(frame_file, "/targets/board/dictionary",
                     "an OpenCV ArUco dictionary name such as \"DICT_5X5_100\", got \"" + name + "\"");
  }
  return cv::aruco::getPredefinedDictionary(it->second);
}

cv::Ptr<cv::aruco::CharucoBoard> MakeBoard(const BoardTarget& board, const std::string& frame_file) {
  if (board.squares_x < 2 || board.squares_y < 2 || !(board.square_mm > 0) || !(board.marker_mm > 0) ||
      board.marker_mm >= board.square_mm) {
    throw InputError(frame_file, "/targets/board",
                     "a ChArUco board of at least 2x2 squares with 0 < marker_mm < square_mm");
  }
  return cv::aruco::CharucoBoard::create(board.squares_x, board.squares_y, static_cast<float>(board.square_mm),
                                         static_cast<float>(board.marker_mm),
                                         DictionaryByName(board.dictionary, frame_file));
}

// world_from_board (docs/calibration.md): half turn about x, board centre to the origin.
Eigen::Matrix3d WorldFromBoardRotation() { return Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal(); }
Eigen::Vector3d WorldFromBoardTranslation(const BoardTarget& board) {
  return {-0.5 * board.squares_x * board.square_mm, 0.5 * board.squares_y * board.square_mm, 0.0};
}

CameraPose PoseFromBoardRvecTvec(const BoardTarget& board, const cv::Vec3d& rvec, const cv::Vec3d& tvec) {
  cv::Mat rotation_cv;
  cv::Rodrigues(rvec, rotation_cv);
  Eigen::Matrix3d camera_from_board;
  cv::cv2eigen(rotation_cv, camera_from_board);
  const Eigen::Vector3d t_camera_from_board(tvec[0], tvec[1], tvec[2]);
  // X_c = R_cb X_b + t_cb and X_w = R_wb X_b + t_wb  =>  X_c = R_cb R_wb^T (X_w - t_wb) + t_cb.
  const Eigen::Matrix3d camera_from_world = camera_from_board * WorldFromBoardRotation().transpose();
  const Eigen::Vector3d t_camera_from_world =
      t_camera_from_board - camera_from_world * WorldFromBoardTranslation(board);
  CameraPose pose;
  pose.rotation = camera_from_world.transpose();
  pose.translation_mm = -camera_from_world.transpose() * t_camera_from_world;
  return pose;
}

cv::Mat CameraMatrix(const CameraIntrinsics& k) {
  return (cv::Mat_<double>(3, 3) << k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
}

}  // namespace

Eigen::Vector3d BoardToWorld(const BoardTarget& board, const Eigen::Vector3d& point_in_board_mm) {
  return WorldFromBoardRotation() * point_in_board_mm + WorldFromBoardTranslation(board);
}

std::vector<Eigen::Vector3d> BoardCornersInWorld(const BoardTarget& board) {
  // ChArUco corner ids run along x first, starting at the corner nearest the board origin
  // (OpenCV CharucoBoard::chessboardCorners).
  std::vector<Eigen::Vector3d> corners;
  for (int y = 1; y < board.squares_y; ++y) {
    for (int x = 1; x < board.squares_x; ++x) {
      corners.push_back(BoardToWorld(board, Eigen::Vector3d(x * board.square_mm, y * board.square_mm, 0.0)));
    }
  }
  return corners;
}

BoardObservation DetectBoard(const Image& frame_rgb, const BoardTarget& board, const std::string& frame_file,
                             int min_corners) {
  const auto charuco = MakeBoard(board, frame_file);
  const cv::Mat grey = internal::GreyCopy(frame_rgb);
  // Stretch so that the board's white paper is near white whatever the exposure.
  const double white = std::max(1e-6, internal::Quantile(grey, 0.99));
  const cv::Mat grey8 = internal::ToDisplay8(grey, white);

  std::vector<std::vector<cv::Point2f>> marker_corners;
  std::vector<int> marker_ids;
  cv::aruco::detectMarkers(grey8, charuco->dictionary, marker_corners, marker_ids);
  BoardObservation observation;
  observation.frame_file = frame_file;
  std::vector<cv::Point2f> corners;
  std::vector<int> ids;
  if (!marker_ids.empty()) {
    cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, grey8, charuco, corners, ids);
  }
  if (!ids.empty()) {
    // OpenCV 4.6's interpolateCornersCharuco leaves its corners half a pixel off on anti-aliased
    // images (measured on rendered boards); cornerSubPix on the linear image is unbiased. Its
    // half-window must stay inside the white margin between a square's corner and the markers
    // next to it, (square - marker) / 2, measured from the markers' apparent size.
    std::vector<double> sides;
    for (const auto& quad : marker_corners) sides.push_back(cv::norm(quad[0] - quad[1]));
    std::nth_element(sides.begin(), sides.begin() + sides.size() / 2, sides.end());
    const double margin_px = sides[sides.size() / 2] * (board.square_mm - board.marker_mm) / (2.0 * board.marker_mm);
    const int window = std::clamp(static_cast<int>(0.8 * margin_px), 2, 10);
    cv::cornerSubPix(grey, corners, cv::Size(window, window), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-4));
  }
  if (static_cast<int>(ids.size()) < min_corners) {
    throw InputError(frame_file, "",
                     "a ChArUco board (" + std::to_string(board.squares_x) + "x" + std::to_string(board.squares_y) +
                         " squares, " + board.dictionary + ") with at least " + std::to_string(min_corners) +
                         " visible corners; found " + std::to_string(marker_ids.size()) + " markers and " +
                         std::to_string(ids.size()) + " corners");
  }
  for (std::size_t i = 0; i < ids.size(); ++i) {
    observation.pixels.emplace_back(corners[i].x, corners[i].y);
    observation.corner_ids.push_back(ids[i]);
  }
  return observation;
}

double BoardReprojectionErrorPx(const CameraModel& camera, const BoardTarget& board,
                                const BoardObservation& observation) {
  const auto corners = BoardCornersInWorld(board);
  double sum = 0.0;
  for (std::size_t i = 0; i < observation.corner_ids.size(); ++i) {
    sum += (camera.Project(corners[observation.corner_ids[i]]) - observation.pixels[i]).squaredNorm();
  }
  return observation.corner_ids.empty() ? 0.0 : std::sqrt(sum / observation.corner_ids.size());
}

BoardPose EstimateBoardPose(const CameraModel& camera, const BoardTarget& board, const BoardObservation& observation) {
  const auto charuco = MakeBoard(board, observation.frame_file);
  std::vector<cv::Point2f> corners;
  for (const auto& p : observation.pixels) corners.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()));
  const cv::Mat distortion(camera.distortion, true);
  cv::Vec3d rvec, tvec;
  const bool found = cv::aruco::estimatePoseCharucoBoard(corners, observation.corner_ids, charuco,
                                                         CameraMatrix(camera.intrinsics), distortion.reshape(1, 1),
                                                         rvec, tvec, false);
  if (!found) {
    throw InputError(observation.frame_file, "",
                     "a ChArUco board seen from a pose that can be solved (at least 4 non-collinear corners)");
  }
  BoardPose result;
  result.pose = PoseFromBoardRvecTvec(board, rvec, tvec);
  CameraModel posed = camera;
  posed.pose = result.pose;
  result.reprojection_error_px = BoardReprojectionErrorPx(posed, board, observation);
  result.corners = static_cast<int>(observation.corner_ids.size());
  return result;
}

BoardPose EstimateBoardPoseFromFrames(const CameraModel& camera, const BoardTarget& board,
                                      const std::vector<BoardObservation>& observations,
                                      std::vector<std::string>* used, double same_placement_px) {
  if (observations.empty()) throw InputError("board frames", "", "at least one board frame");
  const auto best = std::max_element(observations.begin(), observations.end(), [](const auto& a, const auto& b) {
    return a.corner_ids.size() < b.corner_ids.size();
  });
  const BoardPose reference = EstimateBoardPose(camera, board, *best);
  CameraModel posed = camera;
  posed.pose = reference.pose;
  const auto charuco = MakeBoard(board, best->frame_file);
  std::vector<cv::Point3f> object;
  std::vector<cv::Point2f> image;
  std::vector<const BoardObservation*> members;
  for (const auto& o : observations) {
    if (&o != &*best && !(BoardReprojectionErrorPx(posed, board, o) < same_placement_px)) continue;
    members.push_back(&o);
    for (std::size_t i = 0; i < o.corner_ids.size(); ++i) {
      object.push_back(charuco->chessboardCorners.at(o.corner_ids[i]));
      image.emplace_back(static_cast<float>(o.pixels[i].x()), static_cast<float>(o.pixels[i].y()));
    }
  }
  if (used) {
    used->clear();
    for (const auto* m : members) used->push_back(m->frame_file);
  }
  if (members.size() == 1) return reference;
  const cv::Mat distortion = cv::Mat(camera.distortion, true).reshape(1, 1);
  cv::Mat rvec, tvec;
  if (!cv::solvePnP(object, image, CameraMatrix(camera.intrinsics), distortion, rvec, tvec, false, cv::SOLVEPNP_ITERATIVE)) {
    return reference;
  }
  cv::solvePnPRefineLM(object, image, CameraMatrix(camera.intrinsics), distortion, rvec, tvec);
  BoardPose result;
  result.pose = PoseFromBoardRvecTvec(board, cv::Vec3d(rvec), cv::Vec3d(tvec));
  posed.pose = result.pose;
  double sum = 0.0;
  int count = 0;
  for (const auto* m : members) {
    const double rms = BoardReprojectionErrorPx(posed, board, *m);
    sum += rms * rms * m->corner_ids.size();
    count += static_cast<int>(m->corner_ids.size());
  }
  result.reprojection_error_px = std::sqrt(sum / std::max(1, count));
  result.corners = count;
  return result;
}

IntrinsicsFit CalibrateIntrinsics(int width, int height, const BoardTarget& board,
                                  const std::vector<BoardObservation>& observations, const CameraIntrinsics& initial) {
  if (observations.size() < 3) {
    throw InputError(observations.empty() ? std::string("board frames") : observations.front().frame_file, "",
                     "three or more board frames for intrinsics, got " + std::to_string(observations.size()));
  }
  const auto charuco = MakeBoard(board, observations.front().frame_file);
  std::vector<std::vector<cv::Point2f>> all_corners;
  std::vector<std::vector<int>> all_ids;
  for (const auto& observation : observations) {
    std::vector<cv::Point2f> corners;
    for (const auto& p : observation.pixels) corners.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()));
    all_corners.push_back(std::move(corners));
    all_ids.push_back(observation.corner_ids);
  }
  cv::Mat camera_matrix = CameraMatrix(initial);
  cv::Mat distortion = cv::Mat::zeros(1, 5, CV_64F);
  std::vector<cv::Mat> rvecs, tvecs;
  const int flags = (initial.fx > 0 && initial.fy > 0) ? cv::CALIB_USE_INTRINSIC_GUESS : 0;
  const double rms = cv::aruco::calibrateCameraCharuco(all_corners, all_ids, charuco, cv::Size(width, height),
                                                       camera_matrix, distortion, rvecs, tvecs, flags);
  IntrinsicsFit fit;
  fit.intrinsics = {camera_matrix.at<double>(0, 0), camera_matrix.at<double>(1, 1), camera_matrix.at<double>(0, 2),
                    camera_matrix.at<double>(1, 2)};
  for (int i = 0; i < 5; ++i) fit.distortion[i] = distortion.at<double>(0, i);
  fit.reprojection_error_px = rms;
  for (std::size_t i = 0; i < rvecs.size(); ++i) {
    fit.poses.push_back(PoseFromBoardRvecTvec(board, cv::Vec3d(rvecs[i]), cv::Vec3d(tvecs[i])));
  }
  return fit;
}

}  // namespace u3mscan
