#pragma once
// Merging the detections of one multi-scale marker (MSM) over its scales.
//
// Every scale of an MSM shares its centre, so each scale detected gives one estimate
// of the same image point (undistorted pixels). The estimates are merged robustly: the
// coordinate-wise median, then every scale farther than max_deviation_px from it is
// rejected, and the centre is the mean of the scales kept.

#include <opencv2/core.hpp>

#include <vector>

#include "calibproj/detect/detections.h"

namespace calibproj::detect {

// One marker of one pattern as detected in one camera (kept for diagnostics).
struct ScaleRecord {
  int pattern = -1;
  int array = -1;
  int marker = -1;
  int scale_index = -1;
  Quad corners;             // distorted image pixels, OpenCV order
  cv::Point2d centre;       // undistorted pixels: intersection of the undistorted diagonals
  double side_px = 0.0;     // mean side of the detected square, distorted pixels
  int first_frame = -1;     // first camera frame averaged for this detection
  int frame_count = 0;      // frames averaged
  bool in_region = false;   // found by region-of-interest detection
  bool kept = false;        // used in the merged centre
  double deviation_px = 0;  // distance to the median of its MSM's scales
};

struct MergeOptions {
  // Scales farther than this from the median of their MSM are rejected.
  double max_deviation_px = 0.5;
  // Scales an MSM needs (after rejection) to give a centre.
  int min_scales = 1;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

struct MergedCentre {
  int array = -1;
  int marker = -1;
  cv::Point2d centre;  // undistorted pixels
  int scales_kept = 0;
  int scales_rejected = 0;
  cv::Point2d drift{0.0, 0.0};  // the move of the centre for its scales' drift (scale_drift.h)
};

// Merges the records per (array, marker); sets each record's `kept` and `deviation_px`.
// Returns one centre per MSM with at least min_scales kept, sorted by (array, marker).
std::vector<MergedCentre> MergeScales(std::vector<ScaleRecord>* records, const MergeOptions& options);

}  // namespace calibproj::detect
