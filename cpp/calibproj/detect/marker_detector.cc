#include "calibproj/detect/marker_detector.h"

namespace calibproj::detect {

MarkerDetector::MarkerDetector(const MarkerFamily& family, const DetectorOptions& options) : family_(family) {
  if (family.system == MarkerSystemKind::kAruco) {
    aruco_ = std::make_unique<ArucoDetector>(family, options.aruco);
  } else {
    apriltag_ = std::make_unique<AprilTagDetector>(family, options.apriltag);
  }
}

Detections MarkerDetector::Detect(const cv::Mat& gray, const DetectionTuning& tuning) const {
  return aruco_ ? aruco_->Detect(gray, tuning.aruco_threshold_window_px)
                : apriltag_->Detect(gray, tuning.apriltag_min_white_black_diff);
}

}  // namespace calibproj::detect
