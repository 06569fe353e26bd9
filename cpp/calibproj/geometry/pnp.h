#pragma once
// Absolute pose of a calibrated camera from 2D-3D correspondences (OpenCV).

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "calibproj/geometry/homography.h"

namespace calibproj::geometry {

struct PnpOptions {
  double threshold_px = 3.0;  // RANSAC reprojection threshold in this camera's pixels
  int max_iterations = 1000;
  double confidence = 0.9999;
  int min_inliers = 6;
};

struct PnpEstimate {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // cam_from_world
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  std::vector<int> inliers;  // indices into the rows of X
  bool success = false;
  std::string problem;  // why it failed, when not for too few inliers
};

// RANSAC over minimal samples (SQPnP, globally optimal, robust to the planar flip ambiguity), then Levenberg-Marquardt on all inliers.
// pixels are undistorted pixels of the camera with matrix K. Rows that are not finite
// are left out; points that do not spread (all at one place) fail with a problem.
PnpEstimate EstimatePoseRansac(const Points3& X, const Points2& pixels, const Eigen::Matrix3d& K,
                               const PnpOptions& options);

}  // namespace calibproj::geometry
