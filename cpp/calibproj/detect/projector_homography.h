#pragma once
// The homographies from projector pixels to a camera's undistorted pixels, learnt from
// the camera's marker detections. The floor is a plane, so one homography predicts
// where, and how large, every later marker on it appears in the image. A table or cart
// left in the projection is another plane with its own homography: the dominant one
// (most correspondences) is fitted first, then further ones among the correspondences
// it does not explain. The projector pixels that land on a surface are the same for
// every camera, so a marker is predicted with the surface of the nearest projector
// point whose surface is known.

#include <opencv2/core.hpp>

#include <map>
#include <utility>
#include <vector>

#include "calibproj/detect/surface_fit.h"

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
  // A fit whose scale at its points (the square root of its Jacobian's determinant,
  // median over the points) differs from the markers' own (image side over projector
  // side) by more than this factor either way is not taken: MSMs found along one line
  // (a zoomed camera's first finds) fit degenerate homographies exactly.
  double max_scale_ratio = 2.0;
  // Surfaces fitted at most (the dominant one and max_surfaces - 1 more); a further
  // surface needs min_points correspondences of its own.
  int max_surfaces = 3;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

class ProjectorHomography {
 public:
  ProjectorHomography(cv::Size image_size, HomographyOptions options);

  // Adds one correspondence: a marker centre in projector pixels and in undistorted
  // image pixels. The scales of one MSM share their projector centre; they count as
  // one point (at the mean of their image positions).
  // `scale`: the marker's image side over its projector side (0: unknown), which checks
  // the fits.
  void Add(const cv::Point2d& projector, const cv::Point2d& image, double scale = 0.0);

  // Refits from every correspondence when enough new ones arrived since the last fit;
  // returns valid().
  bool Update();
  // Refits from every correspondence now (the last word before the results); returns
  // valid().
  bool Refit();

  bool valid() const { return valid_; }
  const cv::Matx33d& H() const { return H_; }
  // Distinct projector points.
  int point_count() const { return static_cast<int>(points_.size()); }
  double rms_px() const { return rms_px_; }

  // Undistorted image position of a projector pixel on the dominant surface (needs
  // valid()).
  cv::Point2d Map(const cv::Point2d& projector) const;

  // The homography of the surface a marker centred on `projector` lands on: that of
  // the nearest correspondence fitted by one, the dominant one when none is.
  const cv::Matx33d& SurfaceAt(const cv::Point2d& projector) const;
  // Which surface that is: 0 the dominant one, k the k-th further one.
  int SurfaceIndexAt(const cv::Point2d& projector) const;
  // True when a corner of the square of side `side` centred on `centre` lands on
  // another surface than its centre: a marker folded over the edge of a table, which
  // cannot be decoded, or only with a displaced centre.
  bool CrossesSurfaces(const cv::Point2d& centre, double side) const;
  // Surfaces found (1 with the dominant one alone; 0 before valid()).
  int surface_count() const { return valid_ ? 1 + static_cast<int>(more_.size()) : 0; }

 private:
  bool Fit();

  cv::Size image_size_;
  HomographyOptions options_;
  // Whether H's scale at the points `chosen` agrees with the markers' (max_scale_ratio).
  bool ScaleAgrees(const cv::Matx33d& H, const std::vector<cv::Point2d>& projector, const std::vector<double>& scales,
                   const std::vector<int>& chosen) const;

  struct ImageSum {
    cv::Point2d sum;
    int count = 0;
    double scale_sum = 0.0;  // of the known scales
    int scales = 0;
  };
  std::map<std::pair<double, double>, ImageSum> points_;
  int fitted_count_ = 0;
  bool valid_ = false;
  cv::Matx33d H_ = cv::Matx33d::eye();
  double rms_px_ = 0.0;
  std::vector<cv::Matx33d> more_;        // further surfaces
  std::vector<cv::Point2d> labelled_;    // projector points explained by a surface
  std::vector<int> label_;               // 0: the dominant surface, k: more_[k - 1]
  // Surface of each projector point asked for since the last fit.
  mutable std::map<std::pair<double, double>, int> surface_cache_;
};

}  // namespace calibproj::detect
