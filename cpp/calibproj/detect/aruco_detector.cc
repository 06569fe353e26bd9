#include "calibproj/detect/aruco_detector.h"

#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "calibproj/common/limits.h"
#include "calibproj/detect/option_table.h"

namespace calibproj::detect {

namespace {

constexpr int kMaxThresholdWindow = 1001;  // pixels
constexpr int kMaxThresholdWindows = 64;

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument("ArUco options: " + message);
}

// Grey levels between the image's median and its brightest `share` of pixels.
double Contrast(const cv::Mat& gray, double share) {
  int histogram[256] = {0};
  for (int r = 0; r < gray.rows; ++r) {
    const std::uint8_t* row = gray.ptr<std::uint8_t>(r);
    for (int c = 0; c < gray.cols; ++c) ++histogram[row[c]];
  }
  const double total = static_cast<double>(gray.total());
  const auto level_above = [&](double fraction) {
    double count = 0.0;
    for (int level = 255; level >= 0; --level) {
      count += histogram[level];
      if (count >= fraction * total) return level;
    }
    return 0;
  };
  return level_above(share) - level_above(0.5);
}

}  // namespace

void ArucoOptions::Check() const {
  Require(min_marker_perimeter_rate > 0.0, "min_marker_perimeter_rate must be positive");
  Require(max_marker_perimeter_rate > min_marker_perimeter_rate,
          "max_marker_perimeter_rate must exceed min_marker_perimeter_rate");
  Require(adaptive_thresh_win_size_min >= 3, "adaptive_thresh_win_size_min must be at least 3");
  Require(adaptive_thresh_win_size_max >= adaptive_thresh_win_size_min,
          "adaptive_thresh_win_size_max must be at least adaptive_thresh_win_size_min");
  Require(adaptive_thresh_win_size_step > 0, "adaptive_thresh_win_size_step must be positive");
  Require(thresh_constant_contrast_share >= 0.0 && thresh_constant_contrast_share <= 1.0,
          "thresh_constant_contrast_share must be in [0, 1]");
  Require(min_thresh_constant >= 0.0 && min_thresh_constant <= adaptive_thresh_constant,
          "min_thresh_constant must be in [0, adaptive_thresh_constant]");
  // OpenCV thresholds the whole image once per window size.
  Require(adaptive_thresh_win_size_max <= kMaxThresholdWindow,
          "adaptive_thresh_win_size_max must be at most " + std::to_string(kMaxThresholdWindow));
  Require((adaptive_thresh_win_size_max - adaptive_thresh_win_size_min) / adaptive_thresh_win_size_step <
              kMaxThresholdWindows,
          "adaptive_thresh_win_size_min, _max and _step give more than " + std::to_string(kMaxThresholdWindows) +
              " window sizes");
  Require(error_correction_rate >= 0.0 && error_correction_rate <= 1.0, "error_correction_rate must be in [0, 1]");
  Require(perspective_remove_pixel_per_cell >= 2 && perspective_remove_pixel_per_cell <= 32,
          "perspective_remove_pixel_per_cell must be in [2, 32]");
  Require(perspective_remove_ignored_margin_per_cell >= 0.0 && perspective_remove_ignored_margin_per_cell < 0.5,
          "perspective_remove_ignored_margin_per_cell must be in [0, 0.5)");
  refinement.Check();
  VisitArucoOptions(*this, limits::OptionChecker{"ArUco options: "});
}

ArucoDetector::ArucoDetector(const MarkerFamily& family, const ArucoOptions& options)
    : options_(options), dictionary_(ArucoDictionary(family)) {
  options_.Check();
  parameters_ = cv::aruco::DetectorParameters::create();
  parameters_->detectInvertedMarker = options_.inverted;
  parameters_->minMarkerPerimeterRate = options_.min_marker_perimeter_rate;
  parameters_->maxMarkerPerimeterRate = options_.max_marker_perimeter_rate;
  parameters_->adaptiveThreshWinSizeMin = options_.adaptive_thresh_win_size_min;
  parameters_->adaptiveThreshWinSizeMax = options_.adaptive_thresh_win_size_max;
  parameters_->adaptiveThreshWinSizeStep = options_.adaptive_thresh_win_size_step;
  parameters_->adaptiveThreshConstant = options_.adaptive_thresh_constant;
  parameters_->errorCorrectionRate = options_.error_correction_rate;
  parameters_->perspectiveRemovePixelPerCell = options_.perspective_remove_pixel_per_cell;
  parameters_->perspectiveRemoveIgnoredMarginPerCell = options_.perspective_remove_ignored_margin_per_cell;
  // Corners are refined by RefineCorners() in Detect().
  parameters_->cornerRefinementMethod = cv::aruco::CORNER_REFINE_NONE;
}

Detections ArucoDetector::Detect(const cv::Mat& gray, int threshold_window_px) const {
  CheckGrayImage(gray);
  cv::Ptr<cv::aruco::DetectorParameters> parameters = cv::makePtr<cv::aruco::DetectorParameters>(*parameters_);
  if (threshold_window_px > 0) {
    parameters->adaptiveThreshWinSizeMin = std::max(3, threshold_window_px);
    parameters->adaptiveThreshWinSizeMax = parameters->adaptiveThreshWinSizeMin;
  }
  if (options_.thresh_constant_contrast_share > 0.0) {
    const double constant = options_.thresh_constant_contrast_share * Contrast(gray, 0.005);
    parameters->adaptiveThreshConstant =
        std::clamp(constant, options_.min_thresh_constant, options_.adaptive_thresh_constant);
  }
  std::vector<std::vector<cv::Point2f>> corners;
  std::vector<int> ids;
  cv::aruco::detectMarkers(gray, dictionary_, corners, ids, parameters);
  Detections out;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    Quad quad;
    for (int k = 0; k < 4; ++k) quad[k] = cv::Point2d(corners[i][k].x, corners[i][k].y);
    RefineCorners(gray, dictionary_->markerSize + 2, options_.refinement, &quad);
    out.ids.push_back(ids[i]);
    out.corners.push_back(quad);
  }
  SortById(&out);
  return out;
}

}  // namespace calibproj::detect
