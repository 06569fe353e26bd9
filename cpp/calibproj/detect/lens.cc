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
// Newton's steps after a lens table's interpolation: each multiplies the error by the
// table slope's relative error (~1e-3 at 8 px steps for a wide-angle lens), from ~0.01 px.
constexpr int kNewtonSteps = 2;
// A table node is kept when its value, distorted again, lands this close to it, and an
// interpolated point when it does after Newton's steps.
constexpr double kExactNodePx = 1e-6;
constexpr double kResidualPx = 1e-5;

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

bool LensTables::Grid::Interpolate(const cv::Point2d& p, cv::Point2d* out, cv::Matx22d* slope) const {
  const double x = (p.x - origin.x) / step, y = (p.y - origin.y) / step;
  if (!(x >= 0.0 && y >= 0.0 && x < columns - 1 && y < rows - 1)) return false;
  const int column = static_cast<int>(x), row = static_cast<int>(y);
  const std::size_t node = static_cast<std::size_t>(row) * columns + column;
  if (!exact[node] || !exact[node + 1] || !exact[node + columns] || !exact[node + columns + 1]) return false;
  const double fx = x - column, fy = y - row;
  const cv::Point2d* top = &values[node];
  const cv::Point2d* bottom = top + columns;
  *out = (1 - fy) * ((1 - fx) * top[0] + fx * top[1]) + fy * ((1 - fx) * bottom[0] + fx * bottom[1]);
  const cv::Point2d along_x = ((1 - fy) * (top[1] - top[0]) + fy * (bottom[1] - bottom[0])) / step;
  const cv::Point2d along_y = ((1 - fx) * (bottom[0] - top[0]) + fx * (bottom[1] - top[1])) / step;
  *slope = cv::Matx22d(along_x.x, along_y.x, along_x.y, along_y.y);
  return true;
}

LensTables::LensTables(const CameraIntrinsics& lens, cv::Size image_size, double step_px, double margin_px)
    : lens_(lens), model_(lens), identity_(!lens.HasDistortion()) {
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
  const std::vector<cv::Point2d> nodes = undistort_.values;
  undistort_.values = UndistortPixels(lens, nodes);
  // Beyond the radius where the distortion folds back there is no inverse (the iteration
  // stops anywhere): cells with such a node are left to the exact function.
  const std::vector<cv::Point2d> again = Distort(undistort_.values);
  undistort_.exact.resize(nodes.size());
  for (std::size_t i = 0; i < nodes.size(); ++i) undistort_.exact[i] = cv::norm(again[i] - nodes[i]) < kExactNodePx;
}

std::vector<cv::Point2d> LensTables::Undistort(const std::vector<cv::Point2d>& distorted) const {
  if (identity_) return distorted;
  std::vector<cv::Point2d> out(distorted.size());
  std::vector<cv::Matx22d> slopes(distorted.size());
  std::vector<char> on_table(distorted.size());
  for (std::size_t i = 0; i < distorted.size(); ++i) on_table[i] = undistort_.Interpolate(distorted[i], &out[i], &slopes[i]);
  // Newton's steps on Distort(u) = d, the table's slope standing for the inverse Jacobian;
  // a point they leave off (near where the distortion folds) goes to the exact function.
  for (int step = 0; step <= kNewtonSteps; ++step) {
    const std::vector<cv::Point2d> again = Distort(out);
    for (std::size_t i = 0; i < out.size(); ++i) {
      if (step < kNewtonSteps) {
        out[i] -= slopes[i] * (again[i] - distorted[i]);
      } else if (!(cv::norm(again[i] - distorted[i]) <= kResidualPx)) {
        on_table[i] = false;
      }
    }
  }
  std::vector<std::size_t> exact;
  for (std::size_t i = 0; i < out.size(); ++i) {
    if (!on_table[i]) exact.push_back(i);
  }
  if (exact.empty()) return out;
  std::vector<cv::Point2d> points;
  for (const std::size_t i : exact) points.push_back(distorted[i]);
  points = UndistortPixels(lens_, points);
  for (std::size_t k = 0; k < exact.size(); ++k) out[exact[k]] = points[k];
  return out;
}

std::vector<cv::Point2d> LensTables::Distort(const std::vector<cv::Point2d>& undistorted) const {
  if (identity_) return undistorted;
  if (model_.tilted) return DistortPixels(lens_, undistorted);
  std::vector<cv::Point2d> out(undistorted.size());
  const double fx = lens_.K(0, 0), fy = lens_.K(1, 1), cx = lens_.K(0, 2), cy = lens_.K(1, 2);
  for (std::size_t i = 0; i < undistorted.size(); ++i) {
    model_.Project((undistorted[i].x - cx) / fx, (undistorted[i].y - cy) / fy, &out[i].x, &out[i].y);
  }
  return out;
}

}  // namespace calibproj::detect
