#pragma once
// Ceres manifolds of the bundle adjuster.
//
// PlaneManifold: a plane [n, d] (unit normal n, offset d, n . X = d) as the sphere
// S^2 times the line; tangent [dn (2), dd (1)]. With the offset held fixed (the
// COPLANAR scale gauge) the tangent is dn only.
//
// FixedDistancePoseManifold: a pose [w, t] whose translation keeps its length:
// tangent [dw (3), dt on the sphere of radius |t| (2)]. With the gauge camera at
// the origin, |t| of another camera is the distance between the two centres, so
// this fixes the FREE model's scale.
//
// Sphere charts use the Householder basis of sphere.h expressed in a constant
// reference frame Q whose z axis is the initial direction, so the chart is
// never near its singular point.

#include <ceres/manifold.h>

#include <Eigen/Core>
#include <memory>
#include <utility>

namespace calibproj::ba {

class SphereChart {
 public:
  explicit SphereChart(const Eigen::Vector3d& reference_direction);
  Eigen::Matrix<double, 3, 2> Basis(const Eigen::Vector3d& n) const;
  Eigen::Vector3d Plus(const Eigen::Vector3d& n, const Eigen::Vector2d& delta) const;
  Eigen::Vector2d Minus(const Eigen::Vector3d& m, const Eigen::Vector3d& n) const;

 private:
  Eigen::Matrix3d Q_;  // columns: reference frame, Q e_z = reference direction
};

class PlaneManifold final : public ceres::Manifold {
 public:
  PlaneManifold(const Eigen::Vector3d& reference_normal, bool fix_offset)
      : chart_(reference_normal), fix_offset_(fix_offset) {}
  int AmbientSize() const override { return 4; }
  int TangentSize() const override { return fix_offset_ ? 2 : 3; }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override;
  bool PlusJacobian(const double* x, double* jacobian) const override;
  bool Minus(const double* y, const double* x, double* y_minus_x) const override;
  bool MinusJacobian(const double* x, double* jacobian) const override;

 private:
  const SphereChart chart_;
  const bool fix_offset_;
};

class FixedDistancePoseManifold final : public ceres::Manifold {
 public:
  explicit FixedDistancePoseManifold(const Eigen::Vector3d& reference_translation)
      : chart_(reference_translation) {}
  int AmbientSize() const override { return 6; }
  int TangentSize() const override { return 5; }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override;
  bool PlusJacobian(const double* x, double* jacobian) const override;
  bool Minus(const double* y, const double* x, double* y_minus_x) const override;
  bool MinusJacobian(const double* x, double* jacobian) const override;

 private:
  const SphereChart chart_;
};

// The manifold `inner` with `padding` extra tangent directions that Plus ignores.
// Used for speed only: it lets the scale-gauge camera keep a 6-dimensional tangent
// block like every other camera, so Ceres can use its fixed-size <2,3,6> Schur
// eliminator. The extra direction has a zero column in the Jacobian; the trust
// region's diagonal regularisation makes the step along it zero, so the solution is
// that of `inner`. Not a manifold in Ceres's sense (MinusJacobian * PlusJacobian is
// not the identity): covariance is computed with `inner` itself.
class PaddedManifold final : public ceres::Manifold {
 public:
  PaddedManifold(std::unique_ptr<ceres::Manifold> inner, int padding)
      : inner_(std::move(inner)), padding_(padding) {}
  int AmbientSize() const override { return inner_->AmbientSize(); }
  int TangentSize() const override { return inner_->TangentSize() + padding_; }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override {
    return inner_->Plus(x, delta, x_plus_delta);
  }
  bool PlusJacobian(const double* x, double* jacobian) const override;
  bool Minus(const double* y, const double* x, double* y_minus_x) const override;
  bool MinusJacobian(const double* x, double* jacobian) const override;

 private:
  const std::unique_ptr<ceres::Manifold> inner_;
  const int padding_;
};

}  // namespace calibproj::ba
