#pragma once
// Self-calibration on the floor: camera poses, floor points and the lenses of the
// cameras, refined together from raw (distorted) pixels of points on one plane.
//
// Frame: the floor is z = 0; points are [x, y] on it. The gauge (the similarity of
// the floor plane: 2 translations, 1 rotation, 1 scale) is fixed by holding two
// well-observed points far apart constant; every pose is free.
//
// Lenses: per camera a block [f, cx, cy, k1, k2, p1, p2, k3] (lens.h); `refine`
// lists, per camera, the entries that move (empty: the whole lens is held).
//
// Covariance. Per camera, the covariance of its lens block (zero outside the refined
// entries), in the units of the residuals after each camera's rows are divided by
// that camera's residual RMS (so the figures are in that camera's measured noise).
// The points are eliminated (Schur complement); a direction the data do not
// determine gets a variance of order 1e12 times the prior scale, never a silent 0.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "calibproj/ba/bundle_adjuster.h"
#include "calibproj/selfcal/lens.h"

namespace calibproj::selfcal {

using LensMatrix = Eigen::Matrix<double, Eigen::Dynamic, kLensSize, Eigen::RowMajor>;
using FloorMatrix = Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>;
using LensCovariance = Eigen::Matrix<double, kLensSize, kLensSize, Eigen::RowMajor>;

struct Options {
  ba::Loss loss = ba::Loss::kNone;
  double loss_scale_px = 1.0;
  int max_iterations = 100;
  int num_threads = 1;
  bool compute_covariance = true;

  void Check() const;  // std::invalid_argument naming the option
};

struct Data {
  Eigen::VectorXi camera_index;  // per observation
  Eigen::VectorXi point_index;   // per observation
  ba::PixelMatrix observed;      // per observation, raw pixels
  LensMatrix lenses;             // per camera
  std::vector<LensShape> shapes; // per camera
  std::vector<std::vector<int>> refine;  // per camera, LensIndex entries refined
  ba::PoseMatrix poses;          // per camera, cam_from_floor [w, t]
  FloorMatrix points;            // per point, [x, y] on the floor
};

struct Result {
  double initial_cost = 0.0;
  double final_cost = 0.0;
  int iterations = 0;
  std::string termination;
  bool usable = false;
  Eigen::Vector2i gauge_points = Eigen::Vector2i(-1, -1);
  LensMatrix lenses;
  ba::PoseMatrix poses;
  FloorMatrix points;
  ba::PixelMatrix residuals;                  // per observation, NaN where not projectable
  Eigen::VectorXd noise_px;                   // per camera: RMS of one residual coordinate
  // When compute_covariance: the lenses' joint covariance (8C x 8C, camera c in rows and
  // columns 8c to 8c + 7; zero outside the refined entries). Lenses fitted to the same
  // floor points err together: the off-diagonal blocks say how.
  Eigen::MatrixXd lens_covariance;
  // The covariance of camera a's lens with camera b's (std::invalid_argument when either
  // is out of range or no covariance was computed).
  LensCovariance LensCovarianceOf(int a, int b) const;
};

// std::invalid_argument naming the problem: sizes, indices, non-finite values,
// unknown lens entries, a camera or point without observations, fewer than 2 points,
// a point behind a camera that observes it.
void ValidateData(const Data& data, const Options& options);

Result SelfCalibrate(const Data& data, const Options& options);

}  // namespace calibproj::selfcal
