#pragma once
// Camera calibration from ChArUco board frames (OpenCV aruco): the pose of a camera whose manifest
// gives none, and intrinsics + distortion when several board frames are at hand.
//
// Board placement (our convention, docs/calibration.md): the board lies on the sample plane z = 0
// with its centre at the world origin; the board's x axis (along squares_x) is world +x and the
// board's printed "down" (OpenCV's board y) is world -y. So world_from_board is a half turn about x
// plus the shift of the board's centre to the origin.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "capture/camera_model.h"
#include "capture/manifest.h"
#include "core/image.h"

namespace u3mscan {

// Chessboard corners of the board (ChArUco corner id = index) in world coordinates, mm, z = 0.
std::vector<Eigen::Vector3d> BoardCornersInWorld(const BoardTarget& board);
// Board coordinates (OpenCV: origin at a board corner, y along the printed "down") -> world.
Eigen::Vector3d BoardToWorld(const BoardTarget& board, const Eigen::Vector3d& point_in_board_mm);

struct BoardObservation {
  std::string frame_file;
  std::vector<Eigen::Vector2d> pixels;  // sub-pixel ChArUco corners, OpenCV pixel convention
  std::vector<int> corner_ids;          // index into BoardCornersInWorld
};

// Finds the ChArUco corners in a linear frame. Throws InputError naming `frame_file` when the
// dictionary is unknown (field /targets/board/dictionary) or fewer than `min_corners` corners are
// found.
BoardObservation DetectBoard(const Image& frame_rgb, const BoardTarget& board, const std::string& frame_file,
                             int min_corners = 6);

struct BoardPose {
  CameraPose pose;                   // world_from_camera
  double reprojection_error_px = 0;  // RMS over the corners
  int corners = 0;
};
// Pose of a camera with known intrinsics and distortion (cv::aruco::estimatePoseCharucoBoard).
// Throws InputError naming the frame when no pose is found.
BoardPose EstimateBoardPose(const CameraModel& camera, const BoardTarget& board, const BoardObservation& observation);

// The pose from every board frame that shows the board where the best frame (most corners) shows
// it: one solvePnP (then solvePnPRefineLM) over all their corners, so each frame's corner noise
// averages out. A frame counts as the same placement when its corners reproject within
// `same_placement_px` (RMS) under the best frame's own pose; others (a board moved for
// intrinsics) are left out. `used` lists the frames taken. Throws as EstimateBoardPose.
BoardPose EstimateBoardPoseFromFrames(const CameraModel& camera, const BoardTarget& board,
                                      const std::vector<BoardObservation>& observations,
                                      std::vector<std::string>* used, double same_placement_px = 1.0);

struct IntrinsicsFit {
  CameraIntrinsics intrinsics;
  std::array<double, 5> distortion{};
  double reprojection_error_px = 0;  // RMS over all corners of all frames
  std::vector<CameraPose> poses;     // world_from_camera of each observation
};
// Intrinsics and distortion from three or more board views (cv::aruco::calibrateCameraCharuco),
// started from `initial` (the manifest's values). Throws InputError when fewer than three views.
IntrinsicsFit CalibrateIntrinsics(int width, int height, const BoardTarget& board,
                                  const std::vector<BoardObservation>& observations, const CameraIntrinsics& initial);

// RMS distance (px) between the observed corners and the board corners projected by `camera`.
double BoardReprojectionErrorPx(const CameraModel& camera, const BoardTarget& board, const BoardObservation& observation);

}  // namespace u3mscan
