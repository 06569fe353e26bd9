#pragma once
// The homography from projector pixels to a camera's undistorted pixels, learnt from
// the camera's first marker detections. The floor is a plane, so this one homography
// predicts where, and how large, every later marker appears in the image.

#include <opencv2/core.hpp>

#include <map>
#include <utility>
#include <vector>

namespace calibproj::detect {

struct HomographyOptions {
  // Distinct MSM centres needed before the homography is trusted.
  int min_points = 8;
  // The image points must spread over at least this fraction of the image diagonal
  // (square root of the smaller eigenvalue of their covariance), so that the fit
  // extrapolates sensibly.
  double min_spread = 0.02;
  // RANSAC inlier threshold and the inlier share and RMS a fit must reach.
  double ransac_threshold_px = 2.0;
  double min_inlier_share = 0.8;
  double max_rms_px = 1.0;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

class ProjectorHomography {
 public:
  ProjectorHomography(cv::Size image_size, HomographyOptions options);

  // Adds one correspondence: a marker centre in projector pixels and in undistorted
  // image pixels. The scales of one MSM share their projector centre; they count as
  // one point (at the mean of their image positions).
  void Add(const cv::Point2d& projector, const cv::Point2d& image);

  // Refits from every correspondence when enough new ones arrived since the last fit;
  // returns valid().
  bool Update();

  bool valid() const { return valid_; }
  const cv::Matx33d& H() const { return H_; }
  // Distinct projector points.
  int point_count() const { return static_cast<int>(points_.size()); }
  double rms_px() const { return rms_px_; }

  // Undistorted image position of a projector pixel (needs valid()).
  cv::Point2d Map(const cv::Point2d& projector) const;

 private:
  bool Fit();

  cv::Size image_size_;
  HomographyOptions options_;
  struct ImageSum {
    cv::Point2d sum;
    int count = 0;
  };
  std::map<std::pair<double, double>, ImageSum> points_;
  int fitted_count_ = 0;
  bool valid_ = false;
  cv::Matx33d H_ = cv::Matx33d::eye();
  double rms_px_ = 0.0;
};

}  // namespace calibproj::detect
