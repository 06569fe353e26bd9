#pragma once
// AprilTag detection with libapriltag 3, returned in OpenCV's pixel convention and
// corner order so that both marker systems are interchangeable downstream.

#include <memory>
#include <mutex>

#include "calibproj/detect/apriltag_family.h"
#include "calibproj/detect/corner_refinement.h"
#include "calibproj/detect/detections.h"
#include "calibproj/detect/marker_family.h"

struct apriltag_detector;

namespace calibproj::detect {

struct AprilTagOptions {
  // Markers are white on black (as projected). libapriltag only finds the polarity its
  // family defines, so the image is negated before detection.
  bool inverted = false;
  // Quads are searched in an image decimated by this factor. 1 finds small tags
  // (~15 px: 99 % at 1, 25 % at 2) at ~4x the cost.
  float quad_decimate = 1.0f;
  // Gaussian blur (standard deviation, px) before segmentation; 0 = none.
  float quad_sigma = 0.0f;
  int nthreads = 1;
  // Snap quad edges to strong gradients (only acts when quad_decimate > 1).
  bool refine_edges = true;
  double decode_sharpening = 0.25;
  // Bits the decoder may correct; 3 needs very large tables.
  int max_hamming = 2;
  // Minimum contrast (grey levels) between the tag's white and black cells.
  int min_white_black_diff = 5;
  // Sub-pixel corners (see corner_refinement.h) on top of libapriltag's quad fit.
  CornerRefinementOptions refinement;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

class AprilTagDetector {
 public:
  // `family` must be an AprilTag family ("apriltag:<family>").
  AprilTagDetector(const MarkerFamily& family, const AprilTagOptions& options);
  ~AprilTagDetector();
  AprilTagDetector(const AprilTagDetector&) = delete;
  AprilTagDetector& operator=(const AprilTagDetector&) = delete;

  // Markers in one 8-bit grayscale image; throws std::invalid_argument for other
  // images. Calls are serialised: libapriltag's detector is not re-entrant.
  // min_white_black_diff > 0 replaces the options' value for this call.
  Detections Detect(const cv::Mat& gray, int min_white_black_diff = 0) const;

 private:
  AprilTagOptions options_;
  int quad_cells_;
  AprilTagFamilyPtr family_;  // outlives detector_ (members die in reverse order)
  std::unique_ptr<apriltag_detector, void (*)(apriltag_detector*)> detector_;
  mutable std::mutex mutex_;
};

}  // namespace calibproj::detect
