#include "calibproj/selfcal/lens.h"

#include <Eigen/LU>

#include "calibproj/ba/camera.h"

namespace calibproj::selfcal {

bool ProjectThroughLens(const double* lens, const LensShape& shape, const Eigen::Vector3d& p,
                        Eigen::Vector2d* pixel, Eigen::Matrix<double, 2, 3>* d_pixel_d_point,
                        LensJacobian* d_pixel_d_lens) {
  if (!(p.z() > ba::kMinDepth)) return false;
  const double f = lens[kFocal], k1 = lens[kK1], k2 = lens[kK2], p1 = lens[kP1], p2 = lens[kP2], k3 = lens[kK3];
  const double inv_z = 1.0 / p.z();
  const double x = p.x() * inv_z, y = p.y() * inv_z;
  const double r2 = x * x + y * y;
  const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
  const double xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
  const double yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
  const double fy = f * shape.aspect, fs = f * shape.skew_ratio;
  (*pixel) << f * xd + fs * yd + lens[kCx], fy * yd + lens[kCy];
  if (d_pixel_d_point == nullptr && d_pixel_d_lens == nullptr) return true;

  // d(pixel)/d(xd, yd): the pinhole part.
  Eigen::Matrix2d J_pinhole;
  J_pinhole << f, fs, 0.0, fy;
  if (d_pixel_d_point != nullptr) {
    const double d_radial_d_r2 = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);
    const double cross = 2.0 * x * y * d_radial_d_r2 + 2.0 * p1 * x + 2.0 * p2 * y;
    Eigen::Matrix2d J_distortion;  // d(xd, yd)/d(x, y)
    J_distortion << radial + 2.0 * x * x * d_radial_d_r2 + 2.0 * p1 * y + 6.0 * p2 * x, cross,  //
        cross, radial + 2.0 * y * y * d_radial_d_r2 + 6.0 * p1 * y + 2.0 * p2 * x;
    Eigen::Matrix<double, 2, 3> J_normalise;  // d(x, y)/d(p)
    J_normalise << inv_z, 0.0, -x * inv_z, 0.0, inv_z, -y * inv_z;
    *d_pixel_d_point = J_pinhole * J_distortion * J_normalise;
  }
  if (d_pixel_d_lens != nullptr) {
    Eigen::Matrix<double, 2, 5> J_coefficients;  // d(xd, yd)/d(k1, k2, p1, p2, k3)
    J_coefficients << x * r2, x * r2 * r2, 2.0 * x * y, r2 + 2.0 * x * x, x * r2 * r2 * r2,  //
        y * r2, y * r2 * r2, r2 + 2.0 * y * y, 2.0 * x * y, y * r2 * r2 * r2;
    d_pixel_d_lens->col(kFocal) << xd + shape.skew_ratio * yd, shape.aspect * yd;
    d_pixel_d_lens->col(kCx) << 1.0, 0.0;
    d_pixel_d_lens->col(kCy) << 0.0, 1.0;
    d_pixel_d_lens->rightCols<5>() = J_pinhole * J_coefficients;
  }
  return true;
}

}  // namespace calibproj::selfcal

namespace calibproj::selfcal {

void LensOf(const Eigen::Matrix3d& K, const double* distortion, int num_distortion, double* lens, LensShape* shape) {
  lens[kFocal] = K(0, 0);
  lens[kCx] = K(0, 2);
  lens[kCy] = K(1, 2);
  const int opencv_order[5] = {kK1, kK2, kP1, kP2, kK3};
  for (int i = 0; i < 5; ++i) lens[opencv_order[i]] = i < num_distortion ? distortion[i] : 0.0;
  shape->aspect = K(1, 1) / K(0, 0);
  shape->skew_ratio = K(0, 1) / K(0, 0);
}

LensJacobian ResidualByLens(const double* lens, const LensShape& shape, const Eigen::Vector2d& normalised) {
  Eigen::Vector2d pixel;
  Eigen::Matrix<double, 2, 3> by_point;
  LensJacobian by_lens;
  ProjectThroughLens(lens, shape, Eigen::Vector3d(normalised.x(), normalised.y(), 1.0), &pixel, &by_point, &by_lens);
  Eigen::Matrix2d pinhole;
  pinhole << lens[kFocal], shape.skew_ratio * lens[kFocal], 0.0, shape.aspect * lens[kFocal];
  // At z = 1 the derivative by the point's x and y is the one by the normalised coordinates.
  const Eigen::Matrix2d by_normalised = by_point.leftCols<2>();
  return pinhole * by_normalised.inverse() * by_lens;
}

}  // namespace calibproj::selfcal
