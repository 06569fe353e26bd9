#pragma once
// The lens of a camera whose intrinsics are refined: pinhole with one focal length
// (fy = aspect * f, skew = skew_ratio * f, both held at their given ratios) and
// OpenCV's five distortion coefficients, applied to camera-frame points.
//
// Parameter block (kLensSize): [f, cx, cy, k1, k2, p1, p2, k3].
//   x = X/Z, y = Y/Z, r2 = x^2 + y^2, radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3
//   xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2)
//   yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y
//   u = f (xd + skew_ratio yd) + cx,   v = f aspect yd + cy
// That is cv::projectPoints with the 5-coefficient model.

#include <Eigen/Core>

namespace calibproj::selfcal {

constexpr int kLensSize = 8;
enum LensIndex { kFocal = 0, kCx = 1, kCy = 2, kK1 = 3, kK2 = 4, kP1 = 5, kP2 = 6, kK3 = 7 };

using LensJacobian = Eigen::Matrix<double, 2, kLensSize, Eigen::RowMajor>;

struct LensShape {
  double aspect = 1.0;      // fy / fx
  double skew_ratio = 0.0;  // skew / fx
};

// Distorted pixel of the camera-frame point p; false behind the camera. Either
// Jacobian may be null.
bool ProjectThroughLens(const double* lens, const LensShape& shape, const Eigen::Vector3d& p,
                        Eigen::Vector2d* pixel, Eigen::Matrix<double, 2, 3>* d_pixel_d_point,
                        LensJacobian* d_pixel_d_lens);

}  // namespace calibproj::selfcal

namespace calibproj::selfcal {

// The lens block and shape of pinhole intrinsics K (fx, fy, skew, cx, cy) and OpenCV
// distortion [k1, k2, p1, p2, k3] (missing entries 0; more must be 0, as the
// self-calibration refines only these five).
void LensOf(const Eigen::Matrix3d& K, const double* distortion, int num_distortion, double* lens, LensShape* shape);

// How an error of the lens moves a centre's undistorted pixel residual (projected minus
// observed, in the pinhole pixels of K that the bundle adjustment works in): for a
// centre whose undistorted normalised coordinates are `normalised`, d residual / d lens
// = K (dL/dm)^-1 dL/dlens, with L the lens's map from normalised coordinates m to raw
// pixels. A lens error moves the raw pixel's undistortion, not the raw pixel: to first
// order this is the whole of it (the pinhole projection's own change is that of the
// residual over f).
LensJacobian ResidualByLens(const double* lens, const LensShape& shape, const Eigen::Vector2d& normalised);

}  // namespace calibproj::selfcal
