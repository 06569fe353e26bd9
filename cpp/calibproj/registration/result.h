#pragma once
// The result of a registration in the floor frame, with per-camera metrics: what the
// Python Calibration and the standalone executable both write out.

#include <Eigen/Core>
#include <limits>
#include <string>
#include <vector>

#include "calibproj/registration/floor_frame.h"
#include "calibproj/registration/pose_uncertainty.h"
#include "calibproj/registration/reconstruction.h"

namespace calibproj::registration {

struct CameraResult {
  bool registered = false;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // cam_from_world, floor frame
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  std::string failure;
  double mean_px = 0.0, std_px = 0.0;  // reprojection error of the inliers (registered only)
  int observations = 0;                // in the tracks
  int inliers = 0;                     // kept by the outlier filter
  int track2_observations = 0;         // inliers whose point at least two registered cameras see
  int view_score = 0;                  // of all its observations
  // 1 sigma along the worst direction, from the final bundle adjustment's covariance
  // relative to the gauge camera (0 for it); NaN when not determined.
  double rotation_sigma_deg = std::numeric_limits<double>::quiet_NaN();
  double centre_sigma = std::numeric_limits<double>::quiet_NaN();  // floor-frame units
  bool weak = false;  // rotation_sigma_deg above the options' weak_rotation_sigma_deg
};

struct RegistrationResult {
  std::vector<CameraResult> cameras;
  ba::PointMatrix points;           // reconstructed points, floor frame
  std::vector<int> point_index;     // their indices in the tracks
  std::vector<int> registration_order;
  FloorFrame frame;                 // reconstruction frame -> floor frame
  double floor_rms = 0.0;           // RMS height of the floor's points above the floor
  // COPLANAR: the planes found besides the floor, [n, d] with n . X = d in the floor
  // frame (n_z >= 0: a table top has n = e_z and d its height), and per point of
  // `points` its plane (0 the floor, k >= 1 planes[k - 1], -1 off every plane).
  ba::PlaneMatrix planes;
  std::vector<int> point_plane;
  // The registered cameras' joint pose covariance in the floor frame, the cameras named
  // by their index ("0", "1", ...: the caller names them); empty when not computed.
  PoseUncertainty uncertainty;
};

// Floor frame (plane of the COPLANAR model, or a robust plane fit to the FREE points),
// poses, points and metrics of the current state.
RegistrationResult Summarize(const Reconstruction& reconstruction);

}  // namespace calibproj::registration
