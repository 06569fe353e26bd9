#pragma once
// What a calibration knows of its own poses: the joint covariance of every registered
// camera's pose (cross terms included), from the final bundle adjustment, and each
// camera's noise, in the frame and unit of the calibration's results.

#include <Eigen/Core>
#include <string>
#include <vector>

namespace calibproj::registration {

struct PoseUncertainty {
  // The registered cameras, in the covariance's order.
  std::vector<std::string> cameras;
  // The gauge: this camera's pose and one distance (to the floor; in the free model to
  // the camera farthest from it) were held in the bundle adjustment, so every
  // uncertainty is relative to them (its own rows are zero).
  std::string reference;
  // 6C x 6C: per camera [dtheta (rad), dt (calibration unit)] of its world-to-camera pose,
  // R = Exp(dtheta) R_hat and t = t_hat + dt; then, with refined lenses, 8 rows and
  // columns per lens block [f, cx, cy, k1, k2, p1, p2, k3] (selfcal/lens.h), so
  // (6C + 8L) x (6C + 8L) with the poses' cross terms with the lenses.
  Eigen::MatrixXd covariance;
  // Per camera, the noise of its centres (1 sigma per image coordinate, undistorted px)
  // that the covariance assumes.
  std::vector<double> noise_px;
  // Per camera the index of its lens block (-1: its intrinsics taken as exact); empty:
  // every camera's.
  std::vector<int> lens_block;

  static constexpr int kLensSize = 8;

  bool empty() const { return cameras.empty(); }
  int num_lenses() const;
  // Rows of the covariance that camera `k` depends on: its pose's 6, then its lens's 8.
  std::vector<int> ParametersOf(int k) const;
  // std::invalid_argument naming the first inconsistency (sizes, non-finite values, a
  // reference that is not one of the cameras, a noise that is not positive).
  void Check() const;
  // The same in a world scaled by `factor` (dt scales, dtheta does not).
  PoseUncertainty Scaled(double factor) const;
  // The covariance of camera `a` with camera `b` (6 x 6).
  Eigen::Matrix<double, 6, 6> Block(int a, int b) const { return covariance.block<6, 6>(6 * a, 6 * b); }
  int IndexOf(const std::string& camera) const;  // -1 when not there
  // The same with cameras named by their index ("0", "1", ...: as the registration,
  // which knows no names, gives them) renamed to names[index].
  PoseUncertainty Named(const std::vector<std::string>& names) const;
};

}  // namespace calibproj::registration
