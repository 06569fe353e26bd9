#include "calibproj/ba/manifolds.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <vector>

#include "calibproj/ba/sphere.h"

namespace calibproj::ba {

namespace {
using Vec3Map = Eigen::Map<const Eigen::Vector3d>;
}  // namespace

SphereChart::SphereChart(const Eigen::Vector3d& reference_direction) {
  const Eigen::Vector3d z = reference_direction.normalized();
  Q_ = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), z).toRotationMatrix();
}

Eigen::Matrix<double, 3, 2> SphereChart::Basis(const Eigen::Vector3d& n) const {
  return Q_ * TangentBasis(Q_.transpose() * n);
}

Eigen::Vector3d SphereChart::Plus(const Eigen::Vector3d& n, const Eigen::Vector2d& delta) const {
  return Q_ * SpherePlus(Q_.transpose() * n, delta);
}

Eigen::Vector2d SphereChart::Minus(const Eigen::Vector3d& m, const Eigen::Vector3d& n) const {
  return SphereMinus(Q_.transpose() * m, Q_.transpose() * n);
}

bool PlaneManifold::Plus(const double* x, const double* delta, double* x_plus_delta) const {
  Eigen::Map<Eigen::Vector3d>{x_plus_delta} = chart_.Plus(Vec3Map(x), Eigen::Vector2d(delta[0], delta[1]));
  x_plus_delta[3] = fix_offset_ ? x[3] : x[3] + delta[2];
  return true;
}

bool PlaneManifold::PlusJacobian(const double* x, double* jacobian) const {
  const int tangent = TangentSize();
  Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> J(jacobian, 4, tangent);
  J.setZero();
  J.topLeftCorner<3, 2>() = chart_.Basis(Vec3Map(x));
  if (!fix_offset_) J(3, 2) = 1.0;
  return true;
}

bool PlaneManifold::Minus(const double* y, const double* x, double* y_minus_x) const {
  const Eigen::Vector2d dn = chart_.Minus(Vec3Map(y), Vec3Map(x));
  y_minus_x[0] = dn.x();
  y_minus_x[1] = dn.y();
  if (!fix_offset_) y_minus_x[2] = y[3] - x[3];
  return true;
}

bool PlaneManifold::MinusJacobian(const double* x, double* jacobian) const {
  const int tangent = TangentSize();
  Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> J(jacobian, tangent, 4);
  J.setZero();
  J.topLeftCorner<2, 3>() = chart_.Basis(Vec3Map(x)).transpose();
  if (!fix_offset_) J(2, 3) = 1.0;
  return true;
}

bool FixedDistancePoseManifold::Plus(const double* x, const double* delta, double* x_plus_delta) const {
  for (int i = 0; i < 3; ++i) x_plus_delta[i] = x[i] + delta[i];
  const Vec3Map t(x + 3);
  const double length = t.norm();
  Eigen::Map<Eigen::Vector3d>{x_plus_delta + 3} =
      length * chart_.Plus(t / length, Eigen::Vector2d(delta[3], delta[4]));
  return true;
}

bool FixedDistancePoseManifold::PlusJacobian(const double* x, double* jacobian) const {
  Eigen::Map<Eigen::Matrix<double, 6, 5, Eigen::RowMajor>> J(jacobian);
  J.setZero();
  J.topLeftCorner<3, 3>().setIdentity();
  const Vec3Map t(x + 3);
  const double length = t.norm();
  J.bottomRightCorner<3, 2>() = length * chart_.Basis(t / length);
  return true;
}

bool FixedDistancePoseManifold::Minus(const double* y, const double* x, double* y_minus_x) const {
  for (int i = 0; i < 3; ++i) y_minus_x[i] = y[i] - x[i];
  const Vec3Map ty(y + 3);
  const Vec3Map tx(x + 3);
  const Eigen::Vector2d d = chart_.Minus(ty.normalized(), tx.normalized());
  y_minus_x[3] = d.x();
  y_minus_x[4] = d.y();
  return true;
}

bool FixedDistancePoseManifold::MinusJacobian(const double* x, double* jacobian) const {
  Eigen::Map<Eigen::Matrix<double, 5, 6, Eigen::RowMajor>> J(jacobian);
  J.setZero();
  J.topLeftCorner<3, 3>().setIdentity();
  const Vec3Map t(x + 3);
  const double length = t.norm();
  J.bottomRightCorner<2, 3>() = chart_.Basis(t / length).transpose() / length;
  return true;
}

bool PaddedManifold::PlusJacobian(const double* x, double* jacobian) const {
  const int ambient = AmbientSize();
  const int inner_tangent = inner_->TangentSize();
  std::vector<double> inner(ambient * inner_tangent);
  if (!inner_->PlusJacobian(x, inner.data())) return false;
  for (int row = 0; row < ambient; ++row) {
    for (int col = 0; col < TangentSize(); ++col) {
      jacobian[row * TangentSize() + col] = col < inner_tangent ? inner[row * inner_tangent + col] : 0.0;
    }
  }
  return true;
}

bool PaddedManifold::Minus(const double* y, const double* x, double* y_minus_x) const {
  std::fill(y_minus_x + inner_->TangentSize(), y_minus_x + TangentSize(), 0.0);
  return inner_->Minus(y, x, y_minus_x);
}

bool PaddedManifold::MinusJacobian(const double* x, double* jacobian) const {
  const int ambient = AmbientSize();
  std::fill(jacobian, jacobian + TangentSize() * ambient, 0.0);
  return inner_->MinusJacobian(x, jacobian);  // the first rows, row-major
}

}  // namespace calibproj::ba
