#pragma once
// Pinhole camera with fixed intrinsics, applied to undistorted observations.

#include <Eigen/Core>

namespace calibproj::ba {

struct Intrinsics {
  double fx = 1.0, fy = 1.0, cx = 0.0, cy = 0.0, skew = 0.0;
};

// Points closer to the image plane than this (in camera units) are rejected:
// their projection is meaningless and the Jacobian explodes.
constexpr double kMinDepth = 1e-9;

// Pixel of the camera-frame point p and, if d_pixel_d_point is not null,
// its 2x3 Jacobian. Returns false for points not in front of the camera.
inline bool ProjectPoint(const Intrinsics& K, const Eigen::Vector3d& p, Eigen::Vector2d* pixel,
                         Eigen::Matrix<double, 2, 3>* d_pixel_d_point) {
  if (!(p.z() > kMinDepth)) return false;
  const double inv_z = 1.0 / p.z();
  const double xn = p.x() * inv_z;
  const double yn = p.y() * inv_z;
  (*pixel) << K.fx * xn + K.skew * yn + K.cx, K.fy * yn + K.cy;
  if (d_pixel_d_point != nullptr) {
    (*d_pixel_d_point) << K.fx * inv_z, K.skew * inv_z, -(K.fx * xn + K.skew * yn) * inv_z,  //
        0.0, K.fy * inv_z, -K.fy * yn * inv_z;
  }
  return true;
}

}  // namespace calibproj::ba
