#include "calibproj/detect/projector_homography.h"

#include <opencv2/calib3d.hpp>

#include <cmath>
#include <stdexcept>
#include <string>

namespace calibproj::detect {

namespace {

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument("homography options: " + message);
}

// Square root of the smaller eigenvalue of the points' covariance.
double Spread(const std::vector<cv::Point2d>& points) {
  cv::Point2d mean(0, 0);
  for (const auto& p : points) mean += p;
  mean *= 1.0 / static_cast<double>(points.size());
  double xx = 0, xy = 0, yy = 0;
  for (const auto& p : points) {
    const cv::Point2d d = p - mean;
    xx += d.x * d.x;
    xy += d.x * d.y;
    yy += d.y * d.y;
  }
  const double n = static_cast<double>(points.size());
  xx /= n, xy /= n, yy /= n;
  const double half_trace = 0.5 * (xx + yy);
  const double root = std::sqrt(std::max(0.0, half_trace * half_trace - (xx * yy - xy * xy)));
  return std::sqrt(std::max(0.0, half_trace - root));
}

}  // namespace

void HomographyOptions::Check() const {
  Require(min_points >= 4, "min_points must be at least 4");
  Require(min_spread >= 0.0, "min_spread must be non-negative");
  Require(ransac_threshold_px > 0.0, "ransac_threshold_px must be positive");
  Require(min_inlier_share > 0.0 && min_inlier_share <= 1.0, "min_inlier_share must be in (0, 1]");
  Require(max_rms_px > 0.0, "max_rms_px must be positive");
}

ProjectorHomography::ProjectorHomography(cv::Size image_size, HomographyOptions options)
    : image_size_(image_size), options_(options) {
  options_.Check();
}

void ProjectorHomography::Add(const cv::Point2d& projector, const cv::Point2d& image) {
  ImageSum& point = points_[{projector.x, projector.y}];
  point.sum += image;
  ++point.count;
}

bool ProjectorHomography::Update() {
  const int count = point_count();
  // Refit while few points are known, then whenever their number grew by a quarter.
  const bool due = !valid_ ? count > fitted_count_ : count >= fitted_count_ + std::max(4, fitted_count_ / 4);
  if (count >= options_.min_points && due) {
    fitted_count_ = count;
    const bool fitted = Fit();
    valid_ = valid_ || fitted;
  }
  return valid_;
}

bool ProjectorHomography::Fit() {
  std::vector<cv::Point2d> projector, image;
  for (const auto& [key, point] : points_) {
    projector.emplace_back(key.first, key.second);
    image.push_back(point.sum * (1.0 / point.count));
  }
  const double diagonal = std::hypot(image_size_.width, image_size_.height);
  if (Spread(image) < options_.min_spread * diagonal) return false;
  std::vector<unsigned char> inlier_mask;
  const cv::Mat H = cv::findHomography(projector, image, cv::RANSAC, options_.ransac_threshold_px, inlier_mask);
  if (H.empty()) return false;
  const cv::Matx33d candidate(H);
  int inliers = 0;
  double squares = 0.0;
  for (std::size_t i = 0; i < projector.size(); ++i) {
    if (!inlier_mask[i]) continue;
    const cv::Vec3d q = candidate * cv::Vec3d(projector[i].x, projector[i].y, 1.0);
    const cv::Point2d d = cv::Point2d(q[0] / q[2], q[1] / q[2]) - image[i];
    squares += d.dot(d);
    ++inliers;
  }
  const double rms = std::sqrt(squares / std::max(inliers, 1));
  if (inliers < options_.min_inlier_share * point_count() || rms > options_.max_rms_px) return false;
  H_ = candidate;
  rms_px_ = rms;
  return true;
}

cv::Point2d ProjectorHomography::Map(const cv::Point2d& projector) const {
  const cv::Vec3d q = H_ * cv::Vec3d(projector.x, projector.y, 1.0);
  return {q[0] / q[2], q[1] / q[2]};
}

}  // namespace calibproj::detect
