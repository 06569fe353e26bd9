#pragma once
// The camera's pinhole matrix and OpenCV distortion, and moving pixels between the
// distorted image and undistorted pixels of the same K (what tracks hold).

#include <opencv2/core.hpp>

#include <vector>

namespace calibproj::detect {

struct LensModel {
  cv::Matx33d K = cv::Matx33d::eye();
  std::vector<double> dist;  // OpenCV order [k1, k2, p1, p2, k3, ...]; empty = none

  // Throws std::invalid_argument for a singular K or a distortion vector of a length
  // OpenCV does not take (4, 5, 8, 12 or 14).
  void Check() const;
  bool HasDistortion() const;
};

// Undistorted pixels (P = K) of distorted pixels. Iterates until the result, distorted
// again, is within 1e-9 px (OpenCV's default 5 iterations leave pixels of error in the
// corners of wide-angle images).
std::vector<cv::Point2d> UndistortPixels(const LensModel& lens, const std::vector<cv::Point2d>& distorted);

// Distorted pixels of undistorted pixels (same K).
std::vector<cv::Point2d> DistortPixels(const LensModel& lens, const std::vector<cv::Point2d>& undistorted);

// Both mappings, sampled once on grids of nodes `step_px` apart covering the image
// (distorted side) and its undistorted footprint, and interpolated bilinearly: the
// corner refinement maps a few hundred points per marker, which OpenCV's per-call
// iterative undistortion makes costly. The mappings are smooth, so the interpolation
// error stays far below the detection noise (measured in tests); points off the grids
// fall back to the exact functions.
class LensTables {
 public:
  LensTables(const LensModel& lens, cv::Size image_size, double step_px = 2.0, double margin_px = 64.0);

  const LensModel& lens() const { return lens_; }
  std::vector<cv::Point2d> Undistort(const std::vector<cv::Point2d>& distorted) const;
  std::vector<cv::Point2d> Distort(const std::vector<cv::Point2d>& undistorted) const;

 private:
  // Values of a mapping at the nodes of a regular grid.
  struct Grid {
    cv::Point2d origin;
    double step = 1.0;
    int columns = 0, rows = 0;
    std::vector<cv::Point2d> values;  // row-major

    bool Interpolate(const cv::Point2d& p, cv::Point2d* out) const;
  };

  static Grid Sample(cv::Point2d origin, cv::Point2d end, double step);

  LensModel lens_;
  bool identity_;
  Grid undistort_, distort_;
};

}  // namespace calibproj::detect
