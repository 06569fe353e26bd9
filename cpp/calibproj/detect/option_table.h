#pragma once
// Every knob of the marker detectors, by name, in one table: the standalone
// executable's --detector-option NAME=VALUE walks it, with the names the Python
// binding gives the same fields (calibproj.detect_markers keyword options).
//
// visit(name, field) is called once per knob; the refinement's method is not in it
// (it is an enum, named by corner_refinement=none|subpix|edges).

#include "calibproj/detect/apriltag_detector.h"
#include "calibproj/detect/aruco_detector.h"
#include "calibproj/detect/corner_refinement.h"

namespace calibproj::detect {

template <typename RefinementOptionsT, typename Visitor>
void VisitRefinementOptions(RefinementOptionsT& o, Visitor&& visit) {
  visit("window_fraction", o.window_fraction);
  visit("window_min_px", o.window_min_px);
  visit("window_max_px", o.window_max_px);
  visit("max_iterations", o.max_iterations);
  visit("epsilon_px", o.epsilon_px);
  visit("edge_search_fraction", o.edge_search_fraction);
  visit("edge_spacing_px", o.edge_spacing_px);
  visit("edge_min_samples", o.edge_min_samples);
  visit("edge_end_margin", o.edge_end_margin);
  visit("edge_min_contrast", o.edge_min_contrast);
  visit("edge_passes", o.edge_passes);
}

template <typename ArucoOptionsT, typename Visitor>
void VisitArucoOptions(ArucoOptionsT& o, Visitor&& visit) {
  visit("inverted", o.inverted);
  visit("min_marker_perimeter_rate", o.min_marker_perimeter_rate);
  visit("max_marker_perimeter_rate", o.max_marker_perimeter_rate);
  visit("adaptive_thresh_win_size_min", o.adaptive_thresh_win_size_min);
  visit("adaptive_thresh_win_size_max", o.adaptive_thresh_win_size_max);
  visit("adaptive_thresh_win_size_step", o.adaptive_thresh_win_size_step);
  visit("adaptive_thresh_constant", o.adaptive_thresh_constant);
  visit("thresh_constant_contrast_share", o.thresh_constant_contrast_share);
  visit("min_thresh_constant", o.min_thresh_constant);
  visit("error_correction_rate", o.error_correction_rate);
  visit("perspective_remove_pixel_per_cell", o.perspective_remove_pixel_per_cell);
  visit("perspective_remove_ignored_margin_per_cell", o.perspective_remove_ignored_margin_per_cell);
  VisitRefinementOptions(o.refinement, visit);
}

template <typename AprilTagOptionsT, typename Visitor>
void VisitAprilTagOptions(AprilTagOptionsT& o, Visitor&& visit) {
  visit("inverted", o.inverted);
  visit("quad_decimate", o.quad_decimate);
  visit("quad_sigma", o.quad_sigma);
  visit("nthreads", o.nthreads);
  visit("refine_edges", o.refine_edges);
  visit("decode_sharpening", o.decode_sharpening);
  visit("max_hamming", o.max_hamming);
  visit("min_white_black_diff", o.min_white_black_diff);
  VisitRefinementOptions(o.refinement, visit);
}

}  // namespace calibproj::detect
