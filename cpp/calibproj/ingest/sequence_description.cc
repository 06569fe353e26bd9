#include "calibproj/ingest/sequence_description.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <stdexcept>

#include "calibproj/common/limits.h"
#include "calibproj/detect/marker_family.h"
#include "calibproj/formats/files.h"

namespace calibproj::ingest {

namespace {

// Projector frame rates accepted: any real projector lies well inside.
constexpr double kMinFps = 0.1;
constexpr double kMaxFps = 100'000.0;

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument("sequence: " + message);
}

bool Close(double value, double expected) { return std::abs(value - expected) <= 1e-8 + 1e-5 * std::abs(expected); }

}  // namespace

int SequenceDescription::FrameCount() const { return segments.empty() ? 0 : segments.back().last_frame + 1; }

MarkerSystem MarkerSystem::Of(const std::string& spec, bool inverted) {
  const detect::MarkerFamily family = detect::ParseMarkerFamily(spec);
  const detect::MarkerGeometry geometry = detect::GetMarkerGeometry(family);
  MarkerSystem out;
  out.spec = spec;
  out.system = family.SystemName();
  out.family = family.name;
  out.grid_cells = geometry.grid_cells;
  out.quad_cells = geometry.quad_cells;
  out.id_count = detect::MarkerIdCount(family);
  out.inverted = inverted;
  return out;
}

const SegmentSpec& SequenceDescription::SegmentAt(int frame) const {
  if (frame < 0 || frame >= FrameCount()) {
    throw std::out_of_range("frame " + std::to_string(frame) + " outside the sequence (0.." +
                            std::to_string(FrameCount() - 1) + ")");
  }
  const auto after = std::upper_bound(segments.begin(), segments.end(), frame,
                                      [](int f, const SegmentSpec& s) { return f < s.first_frame; });
  return *std::prev(after);
}

int SequenceDescription::PatternIndexAt(int frame) const {
  SegmentAt(frame);  // the range check
  const auto after = std::upper_bound(patterns.begin(), patterns.end(), frame,
                                      [](int f, const PatternSpec& p) { return f < p.first_frame; });
  if (after == patterns.begin() || frame > std::prev(after)->last_frame) return -1;
  return static_cast<int>(std::prev(after) - patterns.begin());
}

std::vector<int> SequenceDescription::MarkersShown(int index) const {
  if (index < 0 || index >= static_cast<int>(patterns.size())) {
    throw std::out_of_range("pattern " + std::to_string(index) + " outside 0.." +
                            std::to_string(static_cast<int>(patterns.size()) - 1));
  }
  std::vector<bool> shown(markers_per_array, true);
  for (const int marker : patterns[index].omitted) shown[marker] = false;
  std::vector<int> out;
  for (int marker = 0; marker < markers_per_array; ++marker) {
    if (shown[marker]) out.push_back(marker);
  }
  return out;
}

void SequenceDescription::Check() const {
  CheckRanges();
  CheckConsistent();
}

void SequenceDescription::CheckRanges() const {
  Require(!markers.spec.empty(), "no marker family");
  try {
    detect::ParseMarkerFamily(markers.spec);
  } catch (const std::invalid_argument& error) {
    Require(false, error.what());
  }
  Require(projector_width > 0 && projector_height > 0 && projector_width <= limits::kMaxImageSide &&
              projector_height <= limits::kMaxImageSide,
          "projector resolution must be in [1, " + std::to_string(limits::kMaxImageSide) + "] per side");
  // The camera frames per projector frame follow from it: an absurd rate would make the
  // light code templates and frame maps of the ingest absurdly long.
  Require(fps >= kMinFps && fps <= kMaxFps, "projector fps must be in [" + limits::Number(kMinFps) + ", " +
                                                limits::Number(kMaxFps) + "], got " + limits::Number(fps));
  Require(arrays > 0 && markers_per_array > 0, "arrays and markers_per_array must be positive");
  const long long expected_centres = static_cast<long long>(arrays) * markers_per_array;
  Require(static_cast<long long>(centres.size()) == expected_centres,
          "expected " + std::to_string(expected_centres) + " centres, got " + std::to_string(centres.size()));
  for (const cv::Point2d& c : centres) Require(std::isfinite(c.x) && std::isfinite(c.y), "centres must be finite");
  Require(!scales.empty(), "no scales");
  for (const double scale : scales) Require(scale > 0.0 && std::isfinite(scale), "scales must be positive numbers");
  Require(marker_px > 0.0 && std::isfinite(marker_px), "marker_px must be a positive number");
  Require(std::isfinite(margin_px), "margin_px must be a number");
  Require(min_gap_modules >= 0.0 && std::isfinite(min_gap_modules), "min_gap_modules must not be negative");
  Require(frames_per_pattern >= 1, "frames_per_pattern must be at least 1");
  Require(!patterns.empty(), "no patterns");
  Require(!segments.empty(), "no segments");
  int expected_first = 0;
  for (const SegmentSpec& s : segments) {
    Require(s.first_frame == expected_first && s.last_frame >= s.first_frame,
            "segments must tile the frames from 0 without gaps");
    Require(s.last_frame < limits::kMaxFrames,
            "the sequence must have fewer than " + std::to_string(limits::kMaxFrames) + " frames");
    Require(s.kind == "white" || s.kind == "black" || s.kind == "start_code" || s.kind == "end_code" ||
                s.kind == "patterns",
            "unknown segment kind '" + s.kind + "'");
    expected_first = s.last_frame + 1;
  }
  start_code.Check("sequence start code");
  end_code.Check("sequence end code");
  Require(start_code.EndFrame() <= end_code.first_frame, "the start code must come before the end code");
  Require(end_code.EndFrame() <= FrameCount(), "the end code ends after the sequence");
  for (std::size_t i = 0; i < patterns.size(); ++i) {
    const PatternSpec& p = patterns[i];
    const std::string where = "pattern " + std::to_string(i) + ": ";
    Require(p.array >= 0 && p.array < arrays, where + "array out of range");
    Require(p.scale_index >= 0 && p.scale_index < static_cast<int>(scales.size()), where + "scale out of range");
    Require(p.marker_side_px > 0.0 && p.marker_side_px <= limits::kMaxImageSide,
            where + "marker side must be in (0, " + std::to_string(limits::kMaxImageSide) + "] px");
    Require(std::isfinite(p.scale), where + "scale must be finite");
    Require(p.first_frame >= 0 && p.last_frame >= p.first_frame && p.last_frame < FrameCount(),
            where + "frames outside the sequence");
    Require(i == 0 || p.first_frame > patterns[i - 1].last_frame, where + "patterns must be in time order");
    for (int m : p.omitted) Require(m >= 0 && m < markers_per_array, where + "omitted marker out of range");
  }
}

void SequenceDescription::CheckConsistent() const {
  // The drawn and detected squares follow from the family: a sequence that says
  // otherwise would be drawn by one tool and detected by another with other geometry.
  const MarkerSystem family = MarkerSystem::Of(markers.spec, markers.inverted);
  Require(markers == family, "the marker geometry given does not match " + markers.spec + " (" + family.system +
                                 " " + family.family + ", " + std::to_string(family.grid_cells) + " and " +
                                 std::to_string(family.quad_cells) + " cells, " + std::to_string(family.id_count) +
                                 " ids)");
  const std::string grid = std::to_string(grid_rows) + "x" + std::to_string(grid_cols);
  Require(projector_width - 2.0 * margin_px > 0.0 && projector_height - 2.0 * margin_px > 0.0,
          "grid " + grid + " with margin " + formats::FormatNumber("%.1f", margin_px) + " px does not fit a " +
              std::to_string(projector_width) + "x" + std::to_string(projector_height) + " projector");
  const long long per_array = static_cast<long long>(grid_rows) * grid_cols;
  Require(grid_rows >= 1 && grid_cols >= 1 && markers_per_array == per_array,
          "centres have " + std::to_string(markers_per_array) + " markers per array, expected " +
              std::to_string(per_array) + " (a " + grid + " grid)");
  Require(markers_per_array <= markers.id_count, std::to_string(markers_per_array) + " markers per array but " +
                                                     markers.spec + " has only " +
                                                     std::to_string(markers.id_count) + " ids");
  const SegmentSpec& start = OnlySegment("start_code");
  const SegmentSpec& end = OnlySegment("end_code");
  const SegmentSpec& span = OnlySegment("patterns");
  const auto check_code = [](const sync::LightCode& code, const SegmentSpec& segment) {
    const int last = code.EndFrame() - 1;
    Require(segment.first_frame == code.first_frame && segment.last_frame == last,
            segment.kind + " spans frames " + std::to_string(code.first_frame) + ".." + std::to_string(last) +
                " but its segment " + std::to_string(segment.first_frame) + ".." + std::to_string(segment.last_frame));
  };
  check_code(start_code, start);
  check_code(end_code, end);
  Require(start_code.bits != end_code.bits, "start and end light codes must differ");
  Require(start.last_frame < span.first_frame && span.last_frame < end.first_frame,
          "expected the start code, then the patterns, then the end code");
  int previous_last = span.first_frame - 1;
  for (std::size_t i = 0; i < patterns.size(); ++i) {
    const PatternSpec& p = patterns[i];
    const std::string where = "pattern " + std::to_string(i);
    Require(p.first_frame > previous_last && p.last_frame <= span.last_frame,
            where + " (frames " + std::to_string(p.first_frame) + ".." + std::to_string(p.last_frame) +
                ") overlaps another pattern or leaves the patterns segment " + std::to_string(span.first_frame) +
                ".." + std::to_string(span.last_frame));
    const long long frames = static_cast<long long>(p.last_frame) - p.first_frame + 1;
    Require(frames == frames_per_pattern, where + " lasts " + std::to_string(frames) +
                                              " frames, expected frames_per_pattern = " +
                                              std::to_string(frames_per_pattern));
    Require(Close(p.scale, scales[p.scale_index]),
            where + ": scale " + formats::PythonFloat(p.scale) + " (index " + std::to_string(p.scale_index) +
                ") is not the layout's scale " + formats::PythonFloat(scales[p.scale_index]));
    const double side = marker_px * p.scale;
    Require(Close(p.marker_side_px, side), where + ": marker side " + formats::PythonFloat(p.marker_side_px) +
                                               " px, expected " + formats::PythonFloat(side) + " px at scale " +
                                               formats::PythonFloat(p.scale));
    previous_last = p.last_frame;
  }
}

const SegmentSpec& SequenceDescription::OnlySegment(const std::string& kind) const {
  const SegmentSpec* found = nullptr;
  int count = 0;
  for (const SegmentSpec& segment : segments) {
    if (segment.kind == kind) {
      found = &segment;
      ++count;
    }
  }
  Require(count == 1, "expected exactly one " + kind + " segment");
  return *found;
}

sync::LightTimeline SequenceDescription::LightLevels() const {
  std::vector<double> levels(FrameCount(), std::numeric_limits<double>::quiet_NaN());
  for (const SegmentSpec& s : segments) {
    for (int frame = s.first_frame; frame <= s.last_frame; ++frame) {
      if (s.kind == "white") levels[frame] = 1.0;
      if (s.kind == "black") levels[frame] = 0.0;
    }
  }
  for (const sync::LightCode* code : {&start_code, &end_code}) {
    for (int frame = code->first_frame; frame < code->EndFrame(); ++frame) {
      levels[frame] = code->bits[(frame - code->first_frame) / code->frames_per_bit];
    }
  }
  return sync::LightTimeline(std::move(levels));
}

detect::PatternMarkers SequenceDescription::Markers(int index) const {
  const PatternSpec& pattern = patterns.at(index);
  detect::PatternMarkers out;
  out.side_px = pattern.marker_side_px;
  out.grid_cells = markers.grid_cells;
  out.quad_cells = markers.quad_cells;
  for (const int marker : MarkersShown(index)) {
    out.ids.push_back(marker);
    out.centres.push_back(centres[pattern.array * markers_per_array + marker]);
  }
  return out;
}

double SequenceDescription::GapModules(int index) const {
  const detect::PatternMarkers shown = Markers(index);
  double nearest = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < shown.centres.size(); ++i) {
    for (std::size_t j = i + 1; j < shown.centres.size(); ++j) {
      const cv::Point2d d = shown.centres[i] - shown.centres[j];
      // Axis-aligned squares: the gap is along the axis where they are farthest apart.
      nearest = std::min(nearest, std::max(std::abs(d.x), std::abs(d.y)));
    }
  }
  return (nearest - shown.side_px) / (shown.side_px / markers.grid_cells);
}

}  // namespace calibproj::ingest

namespace calibproj::ingest {

bool operator==(const MarkerSystem& a, const MarkerSystem& b) {
  return a.spec == b.spec && a.system == b.system && a.family == b.family && a.grid_cells == b.grid_cells &&
         a.quad_cells == b.quad_cells && a.id_count == b.id_count && a.inverted == b.inverted;
}

bool operator==(const PatternSpec& a, const PatternSpec& b) {
  return a.array == b.array && a.scale_index == b.scale_index && a.scale == b.scale &&
         a.marker_side_px == b.marker_side_px && a.first_frame == b.first_frame && a.last_frame == b.last_frame &&
         a.omitted == b.omitted;
}

bool operator==(const SegmentSpec& a, const SegmentSpec& b) {
  return a.kind == b.kind && a.first_frame == b.first_frame && a.last_frame == b.last_frame;
}

bool operator==(const SequenceDescription& a, const SequenceDescription& b) {
  return a.markers == b.markers && a.projector_width == b.projector_width &&
         a.projector_height == b.projector_height && a.fps == b.fps && a.grid_rows == b.grid_rows &&
         a.grid_cols == b.grid_cols && a.arrays == b.arrays && a.markers_per_array == b.markers_per_array &&
         a.marker_px == b.marker_px && a.margin_px == b.margin_px && a.snap_to_pixels == b.snap_to_pixels &&
         a.min_gap_modules == b.min_gap_modules && a.frames_per_pattern == b.frames_per_pattern &&
         a.centres == b.centres && a.scales == b.scales && a.patterns == b.patterns && a.segments == b.segments &&
         a.start_code == b.start_code && a.end_code == b.end_code;
}

}  // namespace calibproj::ingest
