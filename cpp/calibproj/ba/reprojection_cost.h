#pragma once
// Reprojection residuals with hand-derived Jacobians.
//
// Pose block (6): cam_from_world as [w, t], x_cam = R(w) X + t (see rotation.h).
// FREE point block (3): X in world coordinates.
// COPLANAR: plane block (4) [n, d] with unit normal n and n . X = d for points on
// it; point block (2) [a, b] with X = d n + a u1(n) + b u2(n) (sphere.h).
// Residual (2): projected pixel minus observed (undistorted) pixel.
//
// Any Jacobian block may be null. A point not in front of the camera makes
// Evaluate return false, so Ceres rejects the step that led there.
//
// Inside a solve, R(w) and its left Jacobian are the same for every observation of a
// camera: a RotationCache (a Ceres EvaluationCallback) computes them once per camera
// and evaluation point, and costs given the cache read them instead of the pose's
// first three parameters. Costs without a cache are pure functions of their parameters.

#include <ceres/sized_cost_function.h>

#include <Eigen/Core>

#include "calibproj/ba/camera.h"
#include "calibproj/ba/rotation_cache.h"

namespace calibproj::ba {

class FreePointReprojectionCost final : public ceres::SizedCostFunction<2, 6, 3> {
 public:
  FreePointReprojectionCost(const Intrinsics& K, const Eigen::Vector2d& observed,
                            const CachedRotation* rotation = nullptr)
      : K_(K), observed_(observed), rotation_(rotation) {}
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

 private:
  const Intrinsics K_;
  const Eigen::Vector2d observed_;
  const CachedRotation* rotation_;
};

class PlanePointReprojectionCost final : public ceres::SizedCostFunction<2, 6, 4, 2> {
 public:
  PlanePointReprojectionCost(const Intrinsics& K, const Eigen::Vector2d& observed,
                             const CachedRotation* rotation = nullptr)
      : K_(K), observed_(observed), rotation_(rotation) {}
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

 private:
  const Intrinsics K_;
  const Eigen::Vector2d observed_;
  const CachedRotation* rotation_;
};

// World point of plane coordinates (a, b) on the plane [n, d].
Eigen::Vector3d PointOnPlane(const double* plane, const double* ab);

}  // namespace calibproj::ba
