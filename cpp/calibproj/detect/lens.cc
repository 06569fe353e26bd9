#include "calibproj/detect/lens.h"

#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace calibproj::detect {

namespace {

constexpr int kUndistortMaxIterations = 200;
constexpr double kUndistortEpsilonPx = 1e-9;

}  // namespace

void LensModel::Check() const {
  const std::size_t n = dist.size();
  if (n != 0 && n != 4 && n != 5 && n != 8 && n != 12 && n != 14) {
    throw std::invalid_argument("lens: distortion must have 4, 5, 8, 12 or 14 coefficients, got " +
                                std::to_string(n));
  }
  if (!(K(0, 0) > 0.0) || !(K(1, 1) > 0.0) || K(2, 2) != 1.0) {
    throw std::invalid_argument("lens: K must have positive focal lengths and K[2][2] = 1");
  }
}

bool LensModel::HasDistortion() const {
  return std::any_of(dist.begin(), dist.end(), [](double c) { return c != 0.0; });
}

std::vector<cv::Point2d> UndistortPixels(const LensModel& lens, const std::vector<cv::Point2d>& distorted) {
  if (distorted.empty() || !lens.HasDistortion()) return distorted;
  std::vector<cv::Point2d> out;
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, kUndistortMaxIterations,
                                  kUndistortEpsilonPx);
  cv::undistortPoints(distorted, out, lens.K, lens.dist, cv::noArray(), lens.K, criteria);
  return out;
}

std::vector<cv::Point2d> DistortPixels(const LensModel& lens, const std::vector<cv::Point2d>& undistorted) {
  if (undistorted.empty() || !lens.HasDistortion()) return undistorted;
  std::vector<cv::Point3d> rays;
  rays.reserve(undistorted.size());
  for (const cv::Point2d& p : undistorted) {
    rays.emplace_back((p.x - lens.K(0, 2)) / lens.K(0, 0), (p.y - lens.K(1, 2)) / lens.K(1, 1), 1.0);
  }
  std::vector<cv::Point2d> out;
  cv::projectPoints(rays, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), lens.K, lens.dist, out);
  return out;
}

}  // namespace calibproj::detect
