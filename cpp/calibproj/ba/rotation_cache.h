#pragma once
// Per-camera rotation matrices and left Jacobians, computed once per evaluation point
// of a solve instead of once per observation (see reprojection_cost.h).

#include <ceres/evaluation_callback.h>

#include <Eigen/Core>
#include <vector>

namespace calibproj::ba {

struct CachedRotation {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d J_left = Eigen::Matrix3d::Identity();
};

class RotationCache final : public ceres::EvaluationCallback {
 public:
  // poses[c] points at camera c's parameter block [w, t]; it must outlive the cache.
  explicit RotationCache(std::vector<const double*> poses);
  void PrepareForEvaluation(bool evaluate_jacobians, bool new_evaluation_point) override;
  // Recomputes every entry from the current parameter values.
  void Refresh();
  const CachedRotation* Entry(int camera) const { return &entries_[camera]; }

 private:
  std::vector<const double*> poses_;
  std::vector<CachedRotation> entries_;
};

}  // namespace calibproj::ba
