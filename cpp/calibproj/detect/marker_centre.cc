#include "calibproj/detect/marker_centre.h"

#include <cmath>
#include <limits>

namespace calibproj::detect {

cv::Point2d DiagonalIntersection(const Quad& corners) {
  // Homogeneous lines through each diagonal; their cross product is the intersection.
  const auto homogeneous = [](const cv::Point2d& p) { return cv::Vec3d(p.x, p.y, 1.0); };
  const cv::Vec3d diagonal_02 = homogeneous(corners[0]).cross(homogeneous(corners[2]));
  const cv::Vec3d diagonal_13 = homogeneous(corners[1]).cross(homogeneous(corners[3]));
  const cv::Vec3d point = diagonal_02.cross(diagonal_13);
  const double scale = std::abs(diagonal_02[0]) + std::abs(diagonal_02[1]) + std::abs(diagonal_13[0]) +
                       std::abs(diagonal_13[1]);
  if (!(std::abs(point[2]) > 1e-12 * scale * scale)) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    return {nan, nan};
  }
  return {point[0] / point[2], point[1] / point[2]};
}

std::vector<cv::Point2d> MarkerCentres(const std::vector<Quad>& corners) {
  std::vector<cv::Point2d> centres;
  centres.reserve(corners.size());
  for (const Quad& quad : corners) centres.push_back(DiagonalIntersection(quad));
  return centres;
}

}  // namespace calibproj::detect
