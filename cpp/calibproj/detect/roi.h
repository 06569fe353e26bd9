#pragma once
// Region-of-interest detection of the markers of one projected pattern.
//
// With the projector-to-image homography known, each marker's drawn square is mapped
// into the undistorted image, then through the lens distortion into the image; its
// bounding box, padded, is the region searched. Markers too small to decode or not
// wholly inside the image are not searched at all. Regions start on multiples of
// `alignment` pixels so that detectors working on tiles (libapriltag thresholds 4x4
// tiles) see the same tiles as on the whole frame, and the padding covers every
// neighbourhood the detectors and the corner refinement read: a marker found in its
// region has the corners it has in the whole frame.

#include <opencv2/core.hpp>

#include <optional>
#include <vector>

#include "calibproj/detect/detections.h"
#include "calibproj/detect/lens.h"
#include "calibproj/detect/marker_detector.h"
#include "calibproj/detect/projector_homography.h"
#include "calibproj/detect/resolution_limit.h"

namespace calibproj::detect {

struct RoiOptions {
  // Padding around a marker's predicted bounding box: the larger of padding_px and
  // padding_fraction of its predicted side.
  double padding_fraction = 0.25;
  int padding_px = 16;
  // Regions start on multiples of this many pixels.
  int alignment = 8;
  // Markers whose predicted module (cell) is smaller than this are not searched.
  double min_module_px = 1.5;
  // A marker counts as inside the image when its predicted square stays this far
  // from the image edges.
  int border_px = 4;
  // Regions are dropped for one whole-frame detection when their pixels exceed this
  // share of the frame's (both counted as searched, i.e. after shrinking).
  double max_area_fraction = 0.5;
  // A detection counts only within this distance of its predicted centre: the larger
  // of max_offset_px and max_offset_fraction of the predicted side.
  double max_offset_px = 4.0;
  double max_offset_fraction = 0.25;
  // Points per edge of the drawn square mapped through the lens to bound it.
  int edge_points = 4;
  // A marker whose predicted module exceeds target_module_px is detected in its region
  // shrunk by an integer factor (at most max_downscale) that brings the module near
  // that size: detection costs grow with the pixels searched, and its corners are
  // refined at full resolution afterwards anyway. 0 = never shrink.
  double target_module_px = 4.0;
  int max_downscale = 8;
  // ArUco's adaptive threshold window in regions, pixels: one window does, since the
  // marker's size there is known (between min_module_px and about twice
  // target_module_px per module), where a whole frame needs several. 0 keeps the
  // detector's own windows.
  int threshold_window_px = 13;
  // libapriltag's minimum white-black contrast in regions, grey levels: a region holds
  // one projected marker of known contrast, and flat noisy background below this is
  // not segmented at all (1.6x faster, the same centres on the mock OR). 0 keeps the
  // detector's own.
  int min_white_black_diff = 20;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

// Where one marker of a pattern should appear.
struct MarkerPrediction {
  int id = -1;
  cv::Point2d centre;     // distorted image pixels
  double side_px = 0.0;   // shortest side of its drawn square in the image
  double module_px = 0.0; // side_px over the marker's cells
  cv::Rect region;        // padded, aligned, inside the image
  int downscale = 1;      // detected in its region shrunk by this factor
  Quad corners;           // the detector's quad, distorted image pixels, OpenCV order
};

struct PatternPlan {
  std::vector<MarkerPrediction> markers;  // those worth searching
  int too_small = 0;                      // predicted too small to decode
  int outside = 0;                        // not wholly inside the image
  int folded = 0;                         // over the edge between two surfaces
  int unresolvable = 0;                   // of a size this camera has not been decoding
  int redundant = 0;                      // left to larger scales of the same MSM
  bool whole_frame = false;               // one whole-frame detection is cheaper

  const MarkerPrediction* Find(int id) const;
};

// Markers drawn by a pattern: ids and centres in projector pixels, with the side of
// their drawn square (border included) and its number of cells.
struct PatternMarkers {
  std::vector<int> ids;
  std::vector<cv::Point2d> centres;
  double side_px = 0.0;
  int grid_cells = 1;
  int quad_cells = 1;  // cells across the square the detectors return, centred in the grid
};

// The scales of the MSMs of a pattern's array, for leaving a marker to larger scales.
struct ScaleSelection {
  std::vector<double> sides;              // drawn side of each scale, projector pixels
  std::vector<std::vector<int>> omitted;  // markers left out at each scale
  int current = 0;                        // the pattern's scale
  int max_scales = 0;                     // searched scales per MSM at most (0: all)
};

// `limit` (may be null) leaves out markers of sizes the camera does not resolve;
// `selection` (may be null) a marker when max_scales larger scales of its MSM are
// worth searching (larger markers give better centres).
PatternPlan PlanPattern(const ProjectorHomography& homography, const CameraIntrinsics& lens, cv::Size image_size,
                        const PatternMarkers& markers, const RoiOptions& options, const ResolutionLimit* limit,
                        const ScaleSelection* selection = nullptr);

// A grey crop of the frame and where it sits in it.
struct RegionImage {
  cv::Mat gray;
  cv::Point origin;
};

// The detector's markers in `gray` shrunk by an integer `factor` (cv::INTER_AREA, so
// each small pixel is the mean of factor x factor pixels), with corners mapped back to
// the coordinates of `gray`. factor 1 detects on `gray` itself.
Detections DetectDownscaled(const MarkerDetector& detector, const cv::Mat& gray, int factor,
                            const DetectionTuning& tuning = {});

// The detection of one planned marker in its region (shrunk by the marker's downscale
// factor for detection), in whole-frame coordinates: the detection of its id closest
// to the prediction, if within the allowed offset.
std::optional<Quad> DetectInRegion(const MarkerDetector& detector, const MarkerPrediction& marker,
                                   const RegionImage& region, const RoiOptions& options);

// How far from its predicted centre a marker of `side_px` may be found.
double AllowedOffset(double side_px, const RoiOptions& options);

// Keeps the detections of a whole frame that a pattern can show: ids in `ids`, seen
// once, and, when a plan is given, close to their prediction.
Detections FilterDetections(const Detections& found, const std::vector<int>& ids, const PatternPlan* plan,
                            const RoiOptions& options, int* rejected);

}  // namespace calibproj::detect
