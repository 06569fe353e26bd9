#pragma once
// ArUco detection with OpenCV 4.6 contrib (old API: Dictionary, DetectorParameters,
// free function detectMarkers).

#include <opencv2/aruco.hpp>

#include <string>

#include "calibproj/detect/corner_refinement.h"
#include "calibproj/detect/detections.h"
#include "calibproj/detect/marker_family.h"

namespace calibproj::detect {

struct ArucoOptions {
  // Markers are white on black (as projected): also accept inverted markers.
  bool inverted = false;
  // Smallest and largest marker perimeter as a fraction of the image's larger side.
  // OpenCV's default minimum 0.03 drops markers under ~14 px on a 1920 px wide frame.
  double min_marker_perimeter_rate = 0.01;
  double max_marker_perimeter_rate = 4.0;
  // Adaptive thresholding windows tried by OpenCV (odd sizes, min..max by step).
  int adaptive_thresh_win_size_min = 3;
  int adaptive_thresh_win_size_max = 23;
  int adaptive_thresh_win_size_step = 10;
  double adaptive_thresh_constant = 7.0;
  // The threshold's constant follows the image's contrast (its brightest 0.5 % above
  // its median: projected white over the floor), times this share, within
  // [min_thresh_constant, adaptive_thresh_constant]: under room light a marker's white
  // stands only a few grey levels over its surroundings. 0 keeps the fixed constant.
  double thresh_constant_contrast_share = 0.035;
  double min_thresh_constant = 3.0;
  // Fraction of the Hamming-correctable bits OpenCV may correct.
  double error_correction_rate = 0.6;
  // Bits are read from the marker warped to this many pixels per module, each module
  // from its centre only (this share of its side ignored at either end): a marker whose
  // white modules bloom into the black ones (saturation under automatic exposure, blur)
  // keeps its bits where OpenCV's defaults (4 px, 0.13) read a wrong code.
  int perspective_remove_pixel_per_cell = 8;
  double perspective_remove_ignored_margin_per_cell = 0.3;
  // Sub-pixel corners (see corner_refinement.h); OpenCV's own refinement is off.
  CornerRefinementOptions refinement;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

class ArucoDetector {
 public:
  // `family` must be an ArUco family ("aruco:<DICT>").
  ArucoDetector(const MarkerFamily& family, const ArucoOptions& options);

  // Markers in one 8-bit grayscale image; throws std::invalid_argument for other images.
  // threshold_window_px > 0: one adaptive-threshold window of that size instead of the
  // options' range.
  Detections Detect(const cv::Mat& gray, int threshold_window_px = 0) const;

 private:
  ArucoOptions options_;
  cv::Ptr<cv::aruco::Dictionary> dictionary_;
  cv::Ptr<cv::aruco::DetectorParameters> parameters_;
};

}  // namespace calibproj::detect
