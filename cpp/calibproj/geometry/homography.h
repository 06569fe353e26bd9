#pragma once
// Plane-induced homography between two calibrated views and its decomposition.
//
// Points are normalised image coordinates (K^-1 [u, v, 1], last coordinate dropped):
// x2 ~ H x1. For a plane n . X = d in the first camera's frame and the second camera
// at X2 = R X + T, H = R + (T / d) n^T (Hartley & Zisserman, result 13.1).

#include <Eigen/Core>
#include <cstdint>
#include <vector>

namespace calibproj::geometry {

using Points2 = Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>;
using Points3 = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

struct HomographyRansacOptions {
  // Inlier threshold in pixels, applied in each camera's own pixels: the transfer
  // error into camera 1 scaled by focal1 and into camera 2 scaled by focal2.
  double threshold_px = 3.0;
  double focal1 = 1.0;
  double focal2 = 1.0;
  int max_iterations = 2000;
  double confidence = 0.9999;
  std::uint64_t seed = 0;
};

struct HomographyEstimate {
  Eigen::Matrix3d H = Eigen::Matrix3d::Identity();
  std::vector<int> inliers;  // indices into the input correspondences
  bool success = false;
};

// RANSAC over minimal 4-point samples, then a least-squares fit to all inliers.
// Needs at least 4 correspondences; returns success = false when no model has 4 inliers.
HomographyEstimate EstimateHomographyRansac(const Points2& x1, const Points2& x2,
                                            const HomographyRansacOptions& options);

struct PlanarMotion {
  Eigen::Matrix3d R;  // camera 2 from camera 1 rotation
  Eigen::Vector3d t;  // camera 2 from camera 1 translation for a plane at distance 1
  Eigen::Vector3d n;  // plane normal in camera 1, pointing away from camera 1 (n . X = 1)
};

// The decompositions of H (OpenCV) that put the points x1, x2 in front of both cameras;
// usually two remain (the two-fold ambiguity of a planar scene).
std::vector<PlanarMotion> DecomposeHomography(const Eigen::Matrix3d& H, const Points2& x1, const Points2& x2);

}  // namespace calibproj::geometry
