#pragma once
// Moving pixels of OpenCV's point type between a camera's distorted image and
// undistorted pixels of the same K (what tracks hold), as the detectors need it.

#include <opencv2/core.hpp>

#include <vector>

#include "calibproj/formats/camera_intrinsics.h"

namespace calibproj::detect {

using formats::CameraIntrinsics;

// Throws std::invalid_argument "lens: <problem>" for intrinsics a detector cannot use
// (formats::IntrinsicsProblem).
void CheckLens(const CameraIntrinsics& lens);

// Undistorted pixels (P = K) of distorted pixels. Iterates until the result, distorted
// again, is within 1e-9 px (OpenCV's default 5 iterations leave pixels of error in the
// corners of wide-angle images).
std::vector<cv::Point2d> UndistortPixels(const CameraIntrinsics& lens, const std::vector<cv::Point2d>& distorted);

// Distorted pixels of undistorted pixels (same K).
std::vector<cv::Point2d> DistortPixels(const CameraIntrinsics& lens, const std::vector<cv::Point2d>& undistorted);

// Both mappings, fast and to within 1e-4 px, for the corner refinement, which maps a
// few hundred points per marker: OpenCV's per-call iterative undistortion makes that
// costly. Distortion is the model's closed form. Undistortion interpolates a table of
// exact values on a grid of nodes `step_px` apart covering the image (and `margin_px`
// around it), then takes Newton steps on the closed form with the table's own slope
// (the interpolation error, ~0.01 px at 8 px, shrinks a thousandfold per step). Points
// off the table, or where the distortion folds back, go to the exact function.
class LensTables {
 public:
  LensTables(const CameraIntrinsics& lens, cv::Size image_size, double step_px = 8.0, double margin_px = 64.0);

  const CameraIntrinsics& lens() const { return lens_; }
  std::vector<cv::Point2d> Undistort(const std::vector<cv::Point2d>& distorted) const;
  std::vector<cv::Point2d> Distort(const std::vector<cv::Point2d>& undistorted) const;

 private:
  // Values of a mapping at the nodes of a regular grid.
  struct Grid {
    cv::Point2d origin;
    double step = 1.0;
    int columns = 0, rows = 0;
    std::vector<cv::Point2d> values;  // row-major
    std::vector<bool> exact;          // per node, whether its value is the mapping's

    // The bilinear value at p and its derivatives (columns d/dx, d/dy); false off the grid.
    bool Interpolate(const cv::Point2d& p, cv::Point2d* out, cv::Matx22d* slope) const;
  };

  static Grid Sample(cv::Point2d origin, cv::Point2d end, double step);

  CameraIntrinsics lens_;
  formats::DistortionModel model_;
  bool identity_;
  Grid undistort_;
};

}  // namespace calibproj::detect
