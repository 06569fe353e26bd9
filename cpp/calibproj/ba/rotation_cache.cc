#include "calibproj/ba/rotation_cache.h"

#include "calibproj/ba/rotation.h"

namespace calibproj::ba {

RotationCache::RotationCache(std::vector<const double*> poses)
    : poses_(std::move(poses)), entries_(poses_.size()) {
  Refresh();
}

void RotationCache::PrepareForEvaluation(bool /*evaluate_jacobians*/, bool new_evaluation_point) {
  if (new_evaluation_point) Refresh();
}

void RotationCache::Refresh() {
  for (size_t c = 0; c < poses_.size(); ++c) {
    RotationAndLeftJacobian(Eigen::Map<const Eigen::Vector3d>(poses_[c]), &entries_[c].R, &entries_[c].J_left);
  }
}

}  // namespace calibproj::ba
