#include "calibproj/ingest/sequence_description.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "calibproj/common/limits.h"
#include "calibproj/detect/marker_family.h"

namespace calibproj::ingest {

namespace {

// Projector frame rates accepted: any real projector lies well inside.
constexpr double kMinFps = 0.1;
constexpr double kMaxFps = 100'000.0;

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument("sequence: " + message);
}

}  // namespace

int SequenceDescription::FrameCount() const { return segments.empty() ? 0 : segments.back().last_frame + 1; }

void SequenceDescription::Check() const {
  Require(!markers.empty(), "no marker family");
  try {
    detect::ParseMarkerFamily(markers);
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
  for (const double scale : scales) Require(scale > 0.0 && std::isfinite(scale), "scales must be positive numbers");
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

detect::PatternMarkers SequenceDescription::Markers(int index, int grid_cells, int quad_cells) const {
  const PatternSpec& pattern = patterns.at(index);
  detect::PatternMarkers out;
  out.side_px = pattern.marker_side_px;
  out.grid_cells = grid_cells;
  out.quad_cells = quad_cells > 0 ? quad_cells : grid_cells;
  for (int marker = 0; marker < markers_per_array; ++marker) {
    if (std::find(pattern.omitted.begin(), pattern.omitted.end(), marker) != pattern.omitted.end()) continue;
    out.ids.push_back(marker);
    out.centres.push_back(centres[pattern.array * markers_per_array + marker]);
  }
  return out;
}

double SequenceDescription::GapModules(int index, int grid_cells) const {
  const detect::PatternMarkers shown = Markers(index, grid_cells);
  double nearest = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < shown.centres.size(); ++i) {
    for (std::size_t j = i + 1; j < shown.centres.size(); ++j) {
      const cv::Point2d d = shown.centres[i] - shown.centres[j];
      // Axis-aligned squares: the gap is along the axis where they are farthest apart.
      nearest = std::min(nearest, std::max(std::abs(d.x), std::abs(d.y)));
    }
  }
  return (nearest - shown.side_px) / (shown.side_px / grid_cells);
}

}  // namespace calibproj::ingest
