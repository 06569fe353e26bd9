#pragma once
// A projection sequence: what the projector shows in every frame. The one data model
// of sequence.json (formats/sequence_file.h reads and writes it), bound to Python as
// calibproj._core.ingest.Sequence, which the Python package only adds rendering to.
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

// The marker family a sequence draws and how: the spec names it, the rest follows from
// the spec (MarkerSystem::Of) and is kept for the file's readers.
struct MarkerSystem {
  std::string spec;    // e.g. "aruco:4X4_50"
  std::string system;  // "aruco" or "apriltag"
  std::string family;  // the family's name within its system
  int grid_cells = 0;  // the drawn marker's side in modules, border included
  int quad_cells = 0;  // the side of the square whose corners the detector returns
  int id_count = 0;    // ids of the family
  bool inverted = true;  // white markers on black

  // The family of `spec` (std::invalid_argument naming the choices for an unknown one).
  static MarkerSystem Of(const std::string& spec, bool inverted);
};

struct SequenceDescription {
  MarkerSystem markers;
  int projector_width = 0;
  int projector_height = 0;
  double fps = 0.0;
  // The layout the centres were placed by: a grid of grid_rows x grid_cols markers per
  // array, `arrays` arrays, margin_px from the image edge (see calibproj.sequence.layout).
  int grid_rows = 0;
  int grid_cols = 0;
  int arrays = 0;
  int markers_per_array = 0;  // grid_rows * grid_cols
  double marker_px = 0.0;  // side of a marker at scale 1, border included
  double margin_px = 0.0;
  bool snap_to_pixels = true;
  double min_gap_modules = 0.0;  // smallest gap between two markers of a pattern
  int frames_per_pattern = 1;
  std::vector<cv::Point2d> centres;
  std::vector<double> scales;
  std::vector<PatternSpec> patterns;
  std::vector<SegmentSpec> segments;
  sync::LightCode start_code;
  sync::LightCode end_code;

  // Projector frames in the sequence (one past the last segment's last frame).
  int FrameCount() const;
  double DurationS() const { return FrameCount() / fps; }

  // The segment frame `frame` belongs to, and the index of the pattern shown on it (-1
  // between patterns); std::out_of_range outside the sequence.
  const SegmentSpec& SegmentAt(int frame) const;
  int PatternIndexAt(int frame) const;
  // The markers (= ids) pattern `index` draws, ascending.
  std::vector<int> MarkersShown(int index) const;

  // Throws std::invalid_argument describing the first inconsistency: out-of-range
  // values ("sequence: ..."), then parts that disagree with each other (segments tile
  // the frames, codes and patterns inside their segments, the marker family's
  // geometry, centres of the layout's shape, ...).
  void Check() const;

  // Level of every frame: 1 white, 0 black, the code bits, NaN for patterns.
  sync::LightTimeline LightLevels() const;

  // The markers drawn by pattern `index` (ids = marker indices), with their projector
  // centres, drawn side and the family's grid and quad cells.
  detect::PatternMarkers Markers(int index) const;

  // Smallest gap between two drawn markers of pattern `index`, in modules of the
  // family's marker; infinity when it shows one marker.
  double GapModules(int index) const;

 private:
  void CheckRanges() const;
  void CheckConsistent() const;
  const SegmentSpec& OnlySegment(const std::string& kind) const;
};

// Equal when every field is (the file a sequence is written to is then the same).
bool operator==(const MarkerSystem& a, const MarkerSystem& b);
bool operator==(const PatternSpec& a, const PatternSpec& b);
bool operator==(const SegmentSpec& a, const SegmentSpec& b);
bool operator==(const SequenceDescription& a, const SequenceDescription& b);

}  // namespace calibproj::ingest
