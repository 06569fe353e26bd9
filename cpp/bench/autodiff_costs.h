#pragma once
// The reprojection residuals of calibproj/ba/reprojection_cost.h written as templated
// functors for ceres::AutoDiffCostFunction. Benchmark and test reference only: the
// product path uses the hand-derived Jacobians.

#include <ceres/autodiff_cost_function.h>
#include <ceres/rotation.h>

#include "calibproj/ba/bundle_adjuster.h"
#include "calibproj/ba/rotation_cache.h"

namespace calibproj::bench {

template <typename T>
bool ProjectResidual(const ba::Intrinsics& K, const Eigen::Vector2d& observed, const T* pose, const T* X,
                     T* residuals) {
  T p[3];
  ceres::AngleAxisRotatePoint(pose, X, p);
  for (int i = 0; i < 3; ++i) p[i] += pose[3 + i];
  if (!(p[2] > T(ba::kMinDepth))) return false;
  const T xn = p[0] / p[2];
  const T yn = p[1] / p[2];
  residuals[0] = K.fx * xn + K.skew * yn + K.cx - observed.x();
  residuals[1] = K.fy * yn + K.cy - observed.y();
  return true;
}

struct FreePointResidual {
  ba::Intrinsics K;
  Eigen::Vector2d observed;
  template <typename T>
  bool operator()(const T* pose, const T* X, T* residuals) const {
    return ProjectResidual(K, observed, pose, X, residuals);
  }
};

// X = d n + a u1(n) + b u2(n), with the Householder basis of calibproj/ba/sphere.h.
struct PlanePointResidual {
  ba::Intrinsics K;
  Eigen::Vector2d observed;
  template <typename T>
  bool operator()(const T* pose, const T* plane, const T* ab, T* residuals) const {
    const T s = T(1.0) + plane[2];
    const T w = (ab[0] * plane[0] + ab[1] * plane[1]) / s;
    T X[3];
    X[0] = plane[3] * plane[0] + ab[0] - plane[0] * w;
    X[1] = plane[3] * plane[1] + ab[1] - plane[1] * w;
    X[2] = plane[3] * plane[2] - (plane[2] + T(1.0)) * w;
    return ProjectResidual(K, observed, pose, X, residuals);
  }
};

inline ba::CostFactory AutoDiffCosts() {
  return [](ba::Model model, const ba::Intrinsics& K, const Eigen::Vector2d& observed,
            const ba::CachedRotation* /*rotation*/) -> ceres::CostFunction* {
    if (model == ba::Model::kFree) {
      return new ceres::AutoDiffCostFunction<FreePointResidual, 2, 6, 3>(new FreePointResidual{K, observed});
    }
    return new ceres::AutoDiffCostFunction<PlanePointResidual, 2, 6, 4, 2>(new PlanePointResidual{K, observed});
  };
}

}  // namespace calibproj::bench
