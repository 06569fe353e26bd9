#pragma once
// A projection sequence as the ingest of a recording needs it, in plain C++ (filled
// from sequence.json by the Python binding or by the standalone executable).
//
// Time is in projector frames; centres are projector pixels, one per
// (array, marker) at index array * markers_per_array + marker.

#include <opencv2/core.hpp>

#include <string>
#include <vector>

#include "calibproj/detect/roi.h"
#include "calibproj/sync/light_timeline.h"

namespace calibproj::ingest {

// One array of MSMs at one scale, shown on projector frames first_frame..last_frame.
struct PatternSpec {
  int array = 0;
  int scale_index = 0;
  double scale = 1.0;
  double marker_side_px = 0.0;  // side of the drawn marker, border included
  int first_frame = 0;
  int last_frame = 0;
  std::vector<int> omitted;  // markers of the array not drawn at this scale
};

// A run of frames of one kind: "white", "black", "start_code", "end_code", "patterns".
struct SegmentSpec {
  std::string kind;
  int first_frame = 0;
  int last_frame = 0;
};

struct SequenceDescription {
  std::string markers;  // marker family spec, e.g. "aruco:4X4_50"
  bool inverted = true; // white markers on black
  int projector_width = 0;
  int projector_height = 0;
  double fps = 0.0;
  int arrays = 0;
  int markers_per_array = 0;
  double marker_px = 0.0;  // side of a marker at scale 1, border included
  std::vector<cv::Point2d> centres;
  std::vector<double> scales;
  std::vector<PatternSpec> patterns;
  std::vector<SegmentSpec> segments;
  sync::LightCode start_code;
  sync::LightCode end_code;

  // Projector frames in the sequence (one past the last segment's last frame).
  int FrameCount() const;

  // Throws std::invalid_argument describing the first inconsistency.
  void Check() const;

  // Level of every frame: 1 white, 0 black, the code bits, NaN for patterns.
  sync::LightTimeline LightLevels() const;

  // The markers drawn by pattern `index` (ids = marker indices), with their projector
  // centres and drawn side; `grid_cells` is the family's drawn width in cells,
  // `quad_cells` that of the detectors' quad (0: the grid's).
  detect::PatternMarkers Markers(int index, int grid_cells, int quad_cells = 0) const;

  // Smallest gap between two drawn markers of pattern `index`, in modules (of a marker
  // `grid_cells` wide); infinity when it shows one marker.
  double GapModules(int index, int grid_cells) const;
};

}  // namespace calibproj::ingest
