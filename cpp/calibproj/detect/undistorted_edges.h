#pragma once
// Corner refinement that fits a marker's edges as straight lines in undistorted pixels.
//
// A lens with distortion bends the straight edges of a large marker in the image; a
// line fitted to a bent edge, and so its corners, are off (measured: 0.4 px RMS on
// the centres of 70 px markers in a GoPro-like image). Here the edges are still
// located in the recorded (distorted) image, where the pixels are, along intensity
// profiles across them; the located edge points are undistorted (cv::undistortPoints,
// P = K) and the lines are fitted there, where the edges are straight whatever the
// lens. The corners, intersections of neighbouring lines, come out in undistorted
// pixels. Without distortion this is the edge-line refinement of corner_refinement.h.

#include <opencv2/core.hpp>

#include <optional>

#include "calibproj/detect/corner_refinement.h"
#include "calibproj/detect/detections.h"
#include "calibproj/detect/lens.h"

namespace calibproj::detect {

struct UndistortedEdgeOptions {
  // How far each intensity profile reaches into the marker, as a share of one module
  // (it must stay within the border module), and out of it (it must stay clear of the
  // next marker: markers of a pattern may be as little as half a module apart).
  double search_fraction = 0.45;
  double outward_fraction = 0.45;
  // One profile every spacing_px along each edge (undistorted pixels), at least
  // min_samples and at most max_samples (large markers gain nothing from more).
  double spacing_px = 1.0;
  int min_samples = 6;
  int max_samples = 32;
  // Samples along a profile, per pixel, and at most per profile.
  double profile_samples_per_px = 5.0;
  int max_profile_samples = 40;
  // Ends of each edge left out (share of its length), where the other edge blurs in.
  double end_margin = 0.15;
  // Profiles with less contrast than this share of their edge's median are ignored.
  double min_contrast = 0.5;
  // Fits repeated from their own result (each profile is centred better on its edge)
  // until no corner moves, or is predicted to move next (the moves shrink
  // geometrically), by more than tolerance_px, at most `passes` times.
  int passes = 6;
  double tolerance_px = 0.002;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

// Undistorted corners of a marker `cells` modules wide whose corners the detector found
// at `distorted` (whole-image pixels, OpenCV order). `gray` holds the part of the
// image starting at `origin`. Returns nullopt when an edge cannot be fitted or a corner
// would move by more than half a module.
std::optional<Quad> RefineUndistortedCorners(const cv::Mat& gray, const cv::Point& origin, const LensTables& lens,
                                             int cells, const Quad& distorted, const UndistortedEdgeOptions& options);

}  // namespace calibproj::detect
