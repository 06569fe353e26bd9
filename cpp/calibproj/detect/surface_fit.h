#pragma once
// A homography from projector pixels to undistorted image pixels fitted by RANSAC to
// some of a camera's correspondences: one plane (the floor, a table top) the
// projection lands on. Used to plan where markers appear (projector_homography.h) and
// to check the detections at the end (floor_consistency.h).

#include <opencv2/core.hpp>

#include <vector>

namespace calibproj::detect {

// H applied to the point p (non-finite where p maps to infinity).
cv::Point2d ApplyHomography(const cv::Matx33d& H, const cv::Point2d& p);

struct SurfaceFitOptions {
  double threshold_px = 2.0;  // RANSAC's threshold, and the inliers' largest residual
  int max_iterations = 2000;  // OpenCV's defaults
  double confidence = 0.995;
  // Inliers only among those of RANSAC's own model (before its final refinement):
  // stricter on a fit to a few points.
  bool within_ransac_inliers = false;
};

struct SurfaceFit {
  cv::Matx33d H = cv::Matx33d::eye();
  std::vector<int> inliers;  // within the threshold; empty when no fit was found
  double rms_px = 0.0;       // over the inliers
};

// The homography of the correspondences `chosen` (indices into `projector` and
// `image`) and those of them it explains.
SurfaceFit FitSurface(const std::vector<cv::Point2d>& projector, const std::vector<cv::Point2d>& image,
                      const std::vector<int>& chosen, const SurfaceFitOptions& options);

}  // namespace calibproj::detect
