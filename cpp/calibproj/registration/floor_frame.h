#pragma once
// The floor frame of a calibration result (docs/conventions.md): z up, floor z = 0,
// origin at the floor projection of the centroid of the registered camera centres,
// x along the floor projection of the first registered camera's optical axis, and,
// without a metric measurement, the first registered camera at height 1.

#include <Eigen/Core>
#include <vector>

#include "calibproj/ba/bundle_adjuster.h"

namespace calibproj::registration {

// X_floor = scale * M (X - origin).
struct FloorFrame {
  Eigen::Matrix3d M = Eigen::Matrix3d::Identity();
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  double scale = 1.0;
};

// Plane [n, d] (n . X = d, |n| = 1) by least squares, refitted `rounds` times without
// the points farther than k robust sigmas. Needs 3 points (std::invalid_argument).
Eigen::Vector4d FitPlaneRobust(const ba::PointMatrix& points, int rounds = 3, double k = 3.0);

// Frame for the given cam_from_world poses above `plane`; `first` indexes `poses`.
FloorFrame ComputeFloorFrame(const ba::PoseMatrix& poses, int first, const Eigen::Vector4d& plane);

}  // namespace calibproj::registration
