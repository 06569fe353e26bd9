#pragma once
// Rotations as angle-axis vectors w (|w| = angle in radians, w/|w| = axis),
// R(w) = Exp([w]x), the same convention as ceres::AngleAxisToRotationMatrix.

#include <Eigen/Core>

namespace calibproj::ba {

Eigen::Matrix3d Skew(const Eigen::Vector3d& v);

// R(w) by Rodrigues' formula, with a Taylor expansion near w = 0.
Eigen::Matrix3d RotationFromAngleAxis(const Eigen::Vector3d& w);

// Angle-axis of R with |w| <= pi.
Eigen::Vector3d AngleAxisFromRotation(const Eigen::Matrix3d& R);

// R(w) and the left Jacobian J_l(w) together, sharing the trigonometry.
void RotationAndLeftJacobian(const Eigen::Vector3d& w, Eigen::Matrix3d* R, Eigen::Matrix3d* J_left);

// Left Jacobian of SO(3): Exp(w + dw) = Exp(J_l(w) dw) Exp(w) to first order, so
// d(R(w) X)/dw = -[R(w) X]x J_l(w).
Eigen::Matrix3d LeftJacobian(const Eigen::Vector3d& w);

}  // namespace calibproj::ba
