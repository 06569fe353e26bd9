#pragma once
// One detector for any marker family spec ("aruco:..." or "apriltag:...").
// Build it once and reuse it: AprilTag families build their decoding tables here.

#include <memory>

#include "calibproj/detect/apriltag_detector.h"
#include "calibproj/detect/aruco_detector.h"
#include "calibproj/detect/detections.h"
#include "calibproj/detect/marker_family.h"

namespace calibproj::detect {

// Options of both systems; only those of the family's system are used.
struct DetectorOptions {
  ArucoOptions aruco;
  AprilTagOptions apriltag;
};

// Knobs that may change from one call to the next without rebuilding the detector (an
// AprilTag detector builds its decoding tables once, which takes seconds for large
// families). 0 keeps the detector's own value.
struct DetectionTuning {
  int aruco_threshold_window_px = 0;     // one adaptive-threshold window of this size
  int apriltag_min_white_black_diff = 0;  // libapriltag's minimum contrast, grey levels
};

class MarkerDetector {
 public:
  MarkerDetector(const MarkerFamily& family, const DetectorOptions& options);

  // Ids and corners (OpenCV convention and order, sorted by id) of the markers in one
  // 8-bit grayscale image. Throws std::invalid_argument for an empty, tiny or
  // non-8-bit single-channel image.
  Detections Detect(const cv::Mat& gray, const DetectionTuning& tuning = {}) const;

  const MarkerFamily& family() const { return family_; }

 private:
  MarkerFamily family_;
  std::unique_ptr<ArucoDetector> aruco_;
  std::unique_ptr<AprilTagDetector> apriltag_;
};

}  // namespace calibproj::detect
