#pragma once
// Reprojection of a floor point through a camera whose lens is refined.
//
// Blocks: pose (6) cam_from_floor [w, t] with x_cam = R(w) X + t (ba/rotation.h);
// floor point (2) [x, y] with X = (x, y, 0); lens (kLensSize, lens.h).
// Residual (2): distorted projection minus the observed (raw) pixel.
// Evaluate returns false behind the camera, for a non-positive focal length and
// whenever a value it would return is not finite, so Ceres rejects that step.

#include <ceres/sized_cost_function.h>

#include <Eigen/Core>

#include "calibproj/selfcal/lens.h"

namespace calibproj::selfcal {

class PlanarLensCost final : public ceres::SizedCostFunction<2, 6, 2, kLensSize> {
 public:
  PlanarLensCost(const LensShape& shape, const Eigen::Vector2d& observed) : shape_(shape), observed_(observed) {}
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

 private:
  const LensShape shape_;
  const Eigen::Vector2d observed_;
};

}  // namespace calibproj::selfcal
