#include "calibproj/ba/sphere.h"

#include <cmath>

namespace calibproj::ba {

Eigen::Matrix<double, 3, 2> TangentBasis(const Eigen::Vector3d& n) {
  const double s = 1.0 + n.z();
  const Eigen::Vector3d v(n.x(), n.y(), n.z() + 1.0);
  Eigen::Matrix<double, 3, 2> B;
  B.col(0) = Eigen::Vector3d::UnitX() - v * (n.x() / s);
  B.col(1) = Eigen::Vector3d::UnitY() - v * (n.y() / s);
  return B;
}

Eigen::Matrix3d TangentCombinationJacobian(const Eigen::Vector3d& n, double a, double b) {
  // a u1 + b u2 = a e_x + b e_y - v w / s with w = a n_x + b n_y, s = 1 + n_z, v = n + e_z.
  const double s = 1.0 + n.z();
  const double w = a * n.x() + b * n.y();
  const Eigen::Vector3d v(n.x(), n.y(), n.z() + 1.0);
  const Eigen::Vector3d grad_w_over_s(a / s, b / s, -w / (s * s));
  return -(w / s) * Eigen::Matrix3d::Identity() - v * grad_w_over_s.transpose();
}

Eigen::Vector3d SpherePlus(const Eigen::Vector3d& n, const Eigen::Vector2d& delta) {
  const double angle = delta.norm();
  if (angle == 0.0) return n;
  const Eigen::Vector3d direction = TangentBasis(n) * (delta / angle);
  return (std::cos(angle) * n + std::sin(angle) * direction).normalized();
}

Eigen::Vector2d SphereMinus(const Eigen::Vector3d& m, const Eigen::Vector3d& n) {
  const Eigen::Vector2d in_plane = TangentBasis(n).transpose() * m;
  const double sin_angle = in_plane.norm();
  if (sin_angle == 0.0) return Eigen::Vector2d::Zero();
  const double angle = std::atan2(sin_angle, n.dot(m));
  return in_plane * (angle / sin_angle);
}

}  // namespace calibproj::ba
