#include "calibproj/detect/lens.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "calibproj/common/limits.h"

namespace calibproj::detect {

namespace {

constexpr int kUndistortMaxIterations = 200;
constexpr double kUndistortEpsilonPx = 1e-9;
// Nodes of a lens table at most (16 bytes each): a distortion model whose undistorted
// image is larger than this is not one of a real lens.
constexpr double kMaxTableNodes = 1 << 26;

cv::Matx33d CvMatrix(const Eigen::Matrix3d& K) {
  cv::Matx33d out;
  cv::eigen2cv(K, out);
  return out;
}

}  // namespace

void CheckLens(const CameraIntrinsics& lens) {
  if (const std::string problem = formats::IntrinsicsProblem(lens); !problem.empty()) {
    throw std::invalid_argument("lens: " + problem);
  }
}

std::vector<cv::Point2d> UndistortPixels(const CameraIntrinsics& lens, const std::vector<cv::Point2d>& distorted) {
  if (distorted.empty() || !lens.HasDistortion()) return distorted;
  std::vector<cv::Point2d> out;
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, kUndistortMaxIterations,
                                  kUndistortEpsilonPx);
  const cv::Matx33d K = CvMatrix(lens.K);
  cv::undistortPoints(distorted, out, K, lens.dist, cv::noArray(), K, criteria);
  return out;
}

std::vector<cv::Point2d> DistortPixels(const CameraIntrinsics& lens, const std::vector<cv::Point2d>& undistorted) {
  if (undistorted.empty() || !lens.HasDistortion()) return undistorted;
  std::vector<cv::Point3d> rays;
  rays.reserve(undistorted.size());
  for (const cv::Point2d& p : undistorted) {
    rays.emplace_back((p.x - lens.K(0, 2)) / lens.K(0, 0), (p.y - lens.K(1, 2)) / lens.K(1, 1), 1.0);
  }
  std::vector<cv::Point2d> out;
  cv::projectPoints(rays, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), CvMatrix(lens.K), lens.dist, out);
  return out;
}

LensTables::Grid LensTables::Sample(cv::Point2d origin, cv::Point2d end, double step) {
  const double columns = std::ceil((end.x - origin.x) / step) + 1, rows = std::ceil((end.y - origin.y) / step) + 1;
  if (!(columns >= 1.0 && rows >= 1.0 && columns * rows <= kMaxTableNodes)) {
    throw std::invalid_argument("lens tables: the image spans (" + std::to_string(origin.x) + ", " +
                                std::to_string(origin.y) + ")..(" + std::to_string(end.x) + ", " +
                                std::to_string(end.y) + ") px, too large for a table: is the distortion model right?");
  }
  Grid grid;
  grid.origin = origin;
  grid.step = step;
  grid.columns = static_cast<int>(std::ceil((end.x - origin.x) / step)) + 1;
  grid.rows = static_cast<int>(std::ceil((end.y - origin.y) / step)) + 1;
  grid.values.reserve(static_cast<std::size_t>(grid.columns) * grid.rows);
  for (int row = 0; row < grid.rows; ++row) {
    for (int column = 0; column < grid.columns; ++column) {
      grid.values.emplace_back(origin.x + column * step, origin.y + row * step);
    }
  }
  return grid;
}

bool LensTables::Grid::Interpolate(const cv::Point2d& p, cv::Point2d* out) const {
  const double x = (p.x - origin.x) / step, y = (p.y - origin.y) / step;
  if (!(x >= 0.0 && y >= 0.0 && x < columns - 1 && y < rows - 1)) return false;
  const int column = static_cast<int>(x), row = static_cast<int>(y);
  const double fx = x - column, fy = y - row;
  const cv::Point2d* top = &values[static_cast<std::size_t>(row) * columns + column];
  const cv::Point2d* bottom = top + columns;
  *out = (1 - fy) * ((1 - fx) * top[0] + fx * top[1]) + fy * ((1 - fx) * bottom[0] + fx * bottom[1]);
  return true;
}

LensTables::LensTables(const CameraIntrinsics& lens, cv::Size image_size, double step_px, double margin_px)
    : lens_(lens), identity_(!lens.HasDistortion()) {
  if (identity_) return;
  if (!(step_px > 0.0) || !(margin_px >= 0.0)) throw std::invalid_argument("lens tables: bad step or margin");
  if (image_size.width < 1 || image_size.height < 1 || image_size.width > limits::kMaxImageSide ||
      image_size.height > limits::kMaxImageSide) {
    throw std::invalid_argument("lens tables: image size must be in [1, " + std::to_string(limits::kMaxImageSide) +
                                "] pixels per side, got " + std::to_string(image_size.width) + "x" +
                                std::to_string(image_size.height));
  }
  const cv::Point2d low(-margin_px, -margin_px), high(image_size.width + margin_px, image_size.height + margin_px);
  undistort_ = Sample(low, high, step_px);
  undistort_.values = UndistortPixels(lens, undistort_.values);
  // The undistorted footprint of the (margined) image bounds the other grid.
  cv::Point2d footprint_low = undistort_.values.front(), footprint_high = footprint_low;
  for (const auto& p : undistort_.values) {
    footprint_low = {std::min(footprint_low.x, p.x), std::min(footprint_low.y, p.y)};
    footprint_high = {std::max(footprint_high.x, p.x), std::max(footprint_high.y, p.y)};
  }
  distort_ = Sample(footprint_low, footprint_high, step_px);
  distort_.values = DistortPixels(lens, distort_.values);
}

std::vector<cv::Point2d> LensTables::Undistort(const std::vector<cv::Point2d>& distorted) const {
  if (identity_) return distorted;
  std::vector<cv::Point2d> out(distorted.size());
  for (std::size_t i = 0; i < distorted.size(); ++i) {
    if (!undistort_.Interpolate(distorted[i], &out[i])) out[i] = UndistortPixels(lens_, {distorted[i]})[0];
  }
  return out;
}

std::vector<cv::Point2d> LensTables::Distort(const std::vector<cv::Point2d>& undistorted) const {
  if (identity_) return undistorted;
  std::vector<cv::Point2d> out(undistorted.size());
  for (std::size_t i = 0; i < undistorted.size(); ++i) {
    if (!distort_.Interpolate(undistorted[i], &out[i])) out[i] = DistortPixels(lens_, {undistorted[i]})[0];
  }
  return out;
}

}  // namespace calibproj::detect
