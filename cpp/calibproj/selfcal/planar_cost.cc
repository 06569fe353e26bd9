#include "calibproj/selfcal/planar_cost.h"

#include "calibproj/ba/rotation.h"

namespace calibproj::selfcal {

bool PlanarLensCost::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  const double* pose = parameters[0];
  const double* floor = parameters[1];
  const double* lens = parameters[2];
  if (!(lens[kFocal] > 0.0)) return false;
  const Eigen::Map<const Eigen::Vector3d> w(pose);
  const Eigen::Map<const Eigen::Vector3d> t(pose + 3);
  const bool want_pose = jacobians != nullptr && jacobians[0] != nullptr;
  const bool want_floor = jacobians != nullptr && jacobians[1] != nullptr;
  const bool want_lens = jacobians != nullptr && jacobians[2] != nullptr;
  Eigen::Matrix3d R, J_left;
  if (want_pose) {
    ba::RotationAndLeftJacobian(w, &R, &J_left);
  } else {
    R = ba::RotationFromAngleAxis(w);
  }
  const Eigen::Vector3d RX = R.col(0) * floor[0] + R.col(1) * floor[1];
  Eigen::Vector2d pixel;
  Eigen::Matrix<double, 2, 3> J_point;
  LensJacobian J_lens;
  if (!ProjectThroughLens(lens, shape_, RX + t, &pixel, (want_pose || want_floor) ? &J_point : nullptr,
                          want_lens ? &J_lens : nullptr)) {
    return false;
  }
  const Eigen::Vector2d residual = pixel - observed_;
  if (!residual.allFinite()) return false;
  Eigen::Map<Eigen::Vector2d>{residuals} = residual;
  if (want_pose) {
    Eigen::Map<Eigen::Matrix<double, 2, 6, Eigen::RowMajor>> J(jacobians[0]);
    J.leftCols<3>() = -J_point * ba::Skew(RX) * J_left;
    J.rightCols<3>() = J_point;
    if (!J.allFinite()) return false;
  }
  if (want_floor) {
    Eigen::Map<Eigen::Matrix<double, 2, 2, Eigen::RowMajor>> J(jacobians[1]);
    J = J_point * R.leftCols<2>();
    if (!J.allFinite()) return false;
  }
  if (want_lens) {
    Eigen::Map<LensJacobian>{jacobians[2]} = J_lens;
    if (!J_lens.allFinite()) return false;
  }
  return true;
}

}  // namespace calibproj::selfcal
