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

}  // namespace calibproj::detect
