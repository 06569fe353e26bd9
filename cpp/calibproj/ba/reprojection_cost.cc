#include "calibproj/ba/reprojection_cost.h"

#include "calibproj/ba/rotation.h"
#include "calibproj/ba/sphere.h"

namespace calibproj::ba {

namespace {

using RowMajor2x6 = Eigen::Matrix<double, 2, 6, Eigen::RowMajor>;
using RowMajor2x4 = Eigen::Matrix<double, 2, 4, Eigen::RowMajor>;
using RowMajor2x3 = Eigen::Matrix<double, 2, 3, Eigen::RowMajor>;
using RowMajor2x2 = Eigen::Matrix<double, 2, 2, Eigen::RowMajor>;

// Projects the world point X through the pose; fills the residual, the pose
// Jacobian (if asked) and d(residual)/dX (if asked). Returns false behind the camera.
bool ProjectWorldPoint(const Intrinsics& K, const Eigen::Vector2d& observed, const double* pose,
                       const CachedRotation* cached, const Eigen::Vector3d& X, double* residuals, double* J_pose,
                       Eigen::Matrix<double, 2, 3>* J_world_point) {
  const Eigen::Map<const Eigen::Vector3d> w(pose);
  const Eigen::Map<const Eigen::Vector3d> t(pose + 3);
  Eigen::Matrix3d R, J_left;
  if (cached != nullptr) {
    R = cached->R;
    J_left = cached->J_left;
  } else if (J_pose != nullptr) {
    RotationAndLeftJacobian(w, &R, &J_left);
  } else {
    R = RotationFromAngleAxis(w);
  }
  const Eigen::Vector3d RX = R * X;
  const bool want_jacobian = J_pose != nullptr || J_world_point != nullptr;
  Eigen::Vector2d pixel;
  Eigen::Matrix<double, 2, 3> J_pixel;
  if (!ProjectPoint(K, RX + t, &pixel, want_jacobian ? &J_pixel : nullptr)) return false;
  Eigen::Map<Eigen::Vector2d>{residuals} = pixel - observed;
  if (J_pose != nullptr) {
    Eigen::Map<RowMajor2x6> J(J_pose);
    J.leftCols<3>() = -J_pixel * Skew(RX) * J_left;
    J.rightCols<3>() = J_pixel;
  }
  if (J_world_point != nullptr) *J_world_point = J_pixel * R;
  return true;
}

}  // namespace

bool FreePointReprojectionCost::Evaluate(double const* const* parameters, double* residuals,
                                         double** jacobians) const {
  const Eigen::Map<const Eigen::Vector3d> X(parameters[1]);
  double* J_pose = jacobians != nullptr ? jacobians[0] : nullptr;
  const bool want_point = jacobians != nullptr && jacobians[1] != nullptr;
  Eigen::Matrix<double, 2, 3> J_X;
  if (!ProjectWorldPoint(K_, observed_, parameters[0], rotation_, X, residuals, J_pose, want_point ? &J_X : nullptr)) {
    return false;
  }
  if (want_point) Eigen::Map<RowMajor2x3>{jacobians[1]} = J_X;
  return true;
}

Eigen::Vector3d PointOnPlane(const double* plane, const double* ab) {
  const Eigen::Map<const Eigen::Vector3d> n(plane);
  return plane[3] * n + TangentBasis(n) * Eigen::Map<const Eigen::Vector2d>(ab);
}

bool PlanePointReprojectionCost::Evaluate(double const* const* parameters, double* residuals,
                                          double** jacobians) const {
  const double* plane = parameters[1];
  const double* ab = parameters[2];
  const Eigen::Map<const Eigen::Vector3d> n(plane);
  const Eigen::Matrix<double, 3, 2> B = TangentBasis(n);
  const Eigen::Vector3d X = plane[3] * n + B * Eigen::Map<const Eigen::Vector2d>(ab);

  double* J_pose = jacobians != nullptr ? jacobians[0] : nullptr;
  const bool want_plane = jacobians != nullptr && jacobians[1] != nullptr;
  const bool want_ab = jacobians != nullptr && jacobians[2] != nullptr;
  Eigen::Matrix<double, 2, 3> J_X;
  if (!ProjectWorldPoint(K_, observed_, parameters[0], rotation_, X, residuals, J_pose,
                         (want_plane || want_ab) ? &J_X : nullptr)) {
    return false;
  }
  if (want_plane) {
    Eigen::Map<RowMajor2x4> J(jacobians[1]);
    const Eigen::Matrix3d dX_dn =
        plane[3] * Eigen::Matrix3d::Identity() + TangentCombinationJacobian(n, ab[0], ab[1]);
    J.leftCols<3>() = J_X * dX_dn;
    J.col(3) = J_X * n;
  }
  if (want_ab) Eigen::Map<RowMajor2x2>{jacobians[2]} = J_X * B;
  return true;
}

}  // namespace calibproj::ba
