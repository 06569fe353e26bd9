#include "calibproj/ba/rotation.h"

#include <Eigen/Geometry>
#include <cmath>

namespace calibproj::ba {

namespace {

// Below this angle the closed forms lose precision; their Taylor series are used.
constexpr double kSmallAngle = 1e-4;

// a = sin(t)/t, b = (1 - cos(t))/t^2, c = (t - sin(t))/t^3 for t = |w|.
struct AngleCoefficients {
  double a, b, c;
};

AngleCoefficients Coefficients(double theta2) {
  if (theta2 < kSmallAngle * kSmallAngle) {
    return {1.0 - theta2 / 6.0, 0.5 - theta2 / 24.0, 1.0 / 6.0 - theta2 / 120.0};
  }
  const double theta = std::sqrt(theta2);
  const double sin_theta = std::sin(theta);
  return {sin_theta / theta, (1.0 - std::cos(theta)) / theta2, (theta - sin_theta) / (theta2 * theta)};
}

}  // namespace

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d S;
  S << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return S;
}

Eigen::Matrix3d RotationFromAngleAxis(const Eigen::Vector3d& w) {
  const AngleCoefficients k = Coefficients(w.squaredNorm());
  const Eigen::Matrix3d W = Skew(w);
  const Eigen::Matrix3d W2 = W * W;  // same operation order as RotationAndLeftJacobian
  return Eigen::Matrix3d::Identity() + k.a * W + k.b * W2;
}

void RotationAndLeftJacobian(const Eigen::Vector3d& w, Eigen::Matrix3d* R, Eigen::Matrix3d* J_left) {
  const AngleCoefficients k = Coefficients(w.squaredNorm());
  const Eigen::Matrix3d W = Skew(w);
  const Eigen::Matrix3d W2 = W * W;
  *R = Eigen::Matrix3d::Identity() + k.a * W + k.b * W2;
  *J_left = Eigen::Matrix3d::Identity() + k.b * W + k.c * W2;
}

Eigen::Vector3d AngleAxisFromRotation(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  double angle = aa.angle();
  if (angle > M_PI) angle -= 2.0 * M_PI;
  return angle * aa.axis();
}

Eigen::Matrix3d LeftJacobian(const Eigen::Vector3d& w) {
  const AngleCoefficients k = Coefficients(w.squaredNorm());
  const Eigen::Matrix3d W = Skew(w);
  return Eigen::Matrix3d::Identity() + k.b * W + k.c * W * W;
}

}  // namespace calibproj::ba
