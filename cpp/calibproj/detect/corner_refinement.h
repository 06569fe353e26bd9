#pragma once
// Sub-pixel refinement of the corners of a detected square marker.
//
// kSubpix: cv::cornerSubPix with a window scaled to the marker (OpenCV 4.6's own
//   CORNER_REFINE_SUBPIX uses an absolute 5 px half window that spans other edges of
//   small markers). On an L-shaped corner it is pulled towards the inside of the
//   angle by ~0.2 px, which moves the diagonal intersection under rotation and
//   perspective.
// kEdges: every edge is located to sub-pixel precision at many
//   points, a line is fitted through them, and the corners are the intersections of
//   neighbouring lines. Unbiased under rotation and perspective.

#include "calibproj/detect/detections.h"

namespace calibproj::detect {

enum class CornerRefinement { kNone, kSubpix, kEdges };

struct CornerRefinementOptions {
  CornerRefinement method = CornerRefinement::kEdges;
  // cornerSubPix half window: window_fraction x marker side, clamped to [min, max] px.
  double window_fraction = 0.1;
  int window_min_px = 1;
  int window_max_px = 5;
  int max_iterations = 30;
  double epsilon_px = 0.005;
  // Edge fits: half length of the intensity profile taken across an edge, as a fraction
  // of one module (side / cells), so that it stays inside the border module and the
  // quiet zone.
  double edge_search_fraction = 0.45;
  // One profile every edge_spacing_px along each edge, at least edge_min_samples.
  double edge_spacing_px = 1.0;
  int edge_min_samples = 6;
  // Ends of each edge left out (fraction of its length), where the other edge blurs in.
  double edge_end_margin = 0.15;
  // Profiles with less contrast than this fraction of their edge's median are ignored
  // (data cells of the border's colour meet the edges of reversed-border AprilTags).
  double edge_min_contrast = 0.5;
  // Edge fits repeated from their own result (the first may start half a pixel off).
  int edge_passes = 2;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

// Refines the corners of a marker whose detected square is `cells` modules wide in
// place. An edge fit that fails (too few usable profiles, or a corner moving by more
// than half a module) leaves the corners as the previous step left them.
void RefineCorners(const cv::Mat& gray, int cells, const CornerRefinementOptions& options, Quad* corners);

}  // namespace calibproj::detect
