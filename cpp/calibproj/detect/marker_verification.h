#pragma once
// Whether a marker expected at a known place is there: its cells read through its
// refined corners.
//
// Once the projector-to-image homography is known, each marker's corners are predicted
// to a fraction of a module. The edge refinement (undistorted_edges.h) started from
// the prediction finds the marker's corners as it does from a detector's; reading the
// cells of the expected id through those corners then tells whether that marker is
// there. A detector's candidate search (thresholding, contours, polygon fits) is not
// needed for a marker that passes, and a marker that does not is left to the detector.

#include <opencv2/core.hpp>

#include <string>

#include "calibproj/detect/detections.h"
#include "calibproj/detect/lens.h"
#include "calibproj/detect/marker_family.h"

namespace calibproj::detect {

struct VerificationOptions {
  // Every cell's level must lie on its expected side of the middle between the mean
  // levels of the white and the black cells, which must differ by at least this many
  // grey levels.
  double min_contrast = 10.0;
  // Each cell is read as the mean of samples x samples points spread over the middle
  // cell_share of its side (blur and a module of 1.5 px leave its middle clean).
  int samples = 3;
  double cell_share = 0.5;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

// Marker `id`'s cells as the projection shows them (MarkerBits, white on black when
// `inverted`), continuous in memory.
cv::Mat ProjectedCells(const MarkerFamily& family, int id, bool inverted);

// The marker drawn as `bits` (grid x grid CV_8U cells, 0 black, non-zero white, as it
// is projected: inverted already when the sequence inverts its markers) whose
// detector quad (quad_cells modules across, centred in the grid) has the undistorted
// corners `undistorted`: true when `gray` (the part of the image starting at
// `origin`) shows it. Cells read outside `gray` fail the check.
bool ShowsMarker(const cv::Mat& gray, const cv::Point& origin, const LensTables& lens, const Quad& undistorted,
                 const cv::Mat& bits, int quad_cells, const VerificationOptions& options);

}  // namespace calibproj::detect
