// The projection sequence as bound classes of the ingest submodule: Sequence (the core's
// one data model of sequence.json) and its parts MarkerSystem, Pattern and Segment.
// Python's calibproj.sequence.Sequence derives from Sequence and only adds rendering.

#include <pybind11/numpy.h>
#include <pybind11/operators.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <algorithm>
#include <cstdint>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "arrays.h"
#include "calibproj/common/limits.h"
#include "calibproj/formats/files.h"
#include "calibproj/formats/sequence_file.h"
#include "calibproj/ingest/sequence_description.h"
#include "checks.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

using ingest::MarkerSystem;
using ingest::PatternSpec;
using ingest::SegmentSpec;
using ingest::SequenceDescription;

// Centres (arrays, markers, 2) as the core keeps them, array by array.
std::vector<cv::Point2d> CentreList(const DoubleArray& centres) {
  RequireShape(centres, {-1, -1, 2}, "centres");
  RequireFiniteValues(centres, "centres");
  std::vector<cv::Point2d> out;
  out.reserve(static_cast<std::size_t>(centres.size() / 2));
  for (py::ssize_t k = 0; k < centres.size(); k += 2) out.emplace_back(centres.data()[k], centres.data()[k + 1]);
  return out;
}

// A sequence from its parts, checked as the file reader checks one (ValueError "sequence: ...").
SequenceDescription MakeSequence(const MarkerSystem& markers, std::pair<int, int> projector, double fps,
                                 std::pair<int, int> grid, std::vector<double> scales, double marker_px,
                                 double margin_px, bool snap_to_pixels, double min_gap_modules,
                                 int frames_per_pattern, const DoubleArray& centres,
                                 std::vector<PatternSpec> patterns, std::vector<SegmentSpec> segments,
                                 const sync::LightCode& start_code, const sync::LightCode& end_code) {
  SequenceDescription s;
  s.markers = markers;
  std::tie(s.projector_width, s.projector_height) = projector;
  s.fps = fps;
  std::tie(s.grid_rows, s.grid_cols) = grid;
  s.arrays = centres.ndim() == 3 ? static_cast<int>(centres.shape(0)) : 0;
  RequireCount(static_cast<long long>(grid.first) * grid.second, 1, limits::kMaxPoints, "markers per array");
  s.markers_per_array = grid.first * grid.second;
  s.scales = std::move(scales);
  s.marker_px = marker_px;
  s.margin_px = margin_px;
  s.snap_to_pixels = snap_to_pixels;
  s.min_gap_modules = min_gap_modules;
  s.frames_per_pattern = frames_per_pattern;
  s.centres = CentreList(centres);
  if (centres.shape(1) != s.markers_per_array) {
    throw std::invalid_argument("sequence: centres have " + std::to_string(centres.shape(1)) +
                                " markers per array, expected " + std::to_string(s.markers_per_array) + " (a " +
                                std::to_string(grid.first) + "x" + std::to_string(grid.second) + " grid)");
  }
  s.patterns = std::move(patterns);
  s.segments = std::move(segments);
  s.start_code = start_code;
  s.end_code = end_code;
  s.Check();
  return s;
}

void RegisterParts(py::module_& m) {
  py::class_<MarkerSystem>(m, "MarkerSystem",
                           "The marker family a sequence draws: spec, system, family, grid_cells (the drawn "
                           "marker's side in modules, border included), quad_cells (that of the square whose "
                           "corners the detector returns), id_count, and inverted (white markers on black)")
      .def(py::init(&MarkerSystem::Of), py::arg("spec"), py::arg("inverted") = true,
           "The family `spec` names; ValueError naming the choices for an unknown one")
      .def_readonly("spec", &MarkerSystem::spec)
      .def_readonly("system", &MarkerSystem::system)
      .def_readonly("family", &MarkerSystem::family)
      .def_readonly("grid_cells", &MarkerSystem::grid_cells)
      .def_readonly("quad_cells", &MarkerSystem::quad_cells)
      .def_readonly("id_count", &MarkerSystem::id_count)
      .def_readonly("inverted", &MarkerSystem::inverted)
      .def(py::self == py::self)
      .def("__repr__", [](const MarkerSystem& s) {
        return "MarkerSystem('" + s.spec + "', inverted=" + (s.inverted ? "True" : "False") + ")";
      });

  py::class_<PatternSpec>(m, "Pattern",
                          "One array of MSMs at one scale, shown on projector frames first_frame..last_frame "
                          "(inclusive); omitted: the array's markers left out at this scale")
      .def(py::init([](int array, int scale_index, double scale, double marker_side_px, int first_frame,
                       int last_frame, std::vector<int> omitted) {
             return PatternSpec{array, scale_index, scale, marker_side_px, first_frame, last_frame,
                                std::move(omitted)};
           }),
           py::arg("array"), py::arg("scale_index"), py::arg("scale"), py::arg("marker_side_px"),
           py::arg("first_frame"), py::arg("last_frame"), py::arg("omitted") = std::vector<int>{})
      .def_readonly("array", &PatternSpec::array)
      .def_readonly("scale_index", &PatternSpec::scale_index)
      .def_readonly("scale", &PatternSpec::scale)
      .def_readonly("marker_side_px", &PatternSpec::marker_side_px, "the drawn marker's side, border included")
      .def_readonly("first_frame", &PatternSpec::first_frame)
      .def_readonly("last_frame", &PatternSpec::last_frame)
      .def_property_readonly("omitted", [](const PatternSpec& p) { return py::tuple(py::cast(p.omitted)); })
      .def(py::self == py::self)
      .def("__repr__", [](const PatternSpec& p) {
        return "Pattern(array " + std::to_string(p.array) + ", scale " + formats::PythonFloat(p.scale) +
               ", frames " + std::to_string(p.first_frame) + ".." + std::to_string(p.last_frame) + ")";
      });

  py::class_<SegmentSpec>(m, "Segment",
                          "A run of projector frames first_frame..last_frame (inclusive) of one kind: white, "
                          "black, start_code, end_code or patterns")
      .def(py::init([](std::string kind, int first_frame, int last_frame) {
             return SegmentSpec{std::move(kind), first_frame, last_frame};
           }),
           py::arg("kind"), py::arg("first_frame"), py::arg("last_frame"))
      .def_readonly("kind", &SegmentSpec::kind)
      .def_readonly("first_frame", &SegmentSpec::first_frame)
      .def_readonly("last_frame", &SegmentSpec::last_frame)
      .def_property_readonly("frame_count", [](const SegmentSpec& s) { return s.last_frame - s.first_frame + 1; })
      .def(py::self == py::self)
      .def("__repr__", [](const SegmentSpec& s) {
        return "Segment('" + s.kind + "', " + std::to_string(s.first_frame) + ".." + std::to_string(s.last_frame) +
               ")";
      });
}

}  // namespace

void register_sequence(py::module_& m) {
  RegisterParts(m);
  py::class_<SequenceDescription>(
      m, "Sequence",
      "A projection sequence: what the projector shows in every frame (the one data model of sequence.json, "
      "read and written by the core). Built from its parts, checked as the file reader checks one, and not "
      "changed afterwards.")
      .def(py::init(&MakeSequence), py::arg("markers"), py::arg("projector"), py::arg("fps"), py::arg("grid"),
           py::arg("scales"), py::arg("marker_px"), py::arg("margin_px"), py::arg("snap_to_pixels"),
           py::arg("min_gap_modules"), py::arg("frames_per_pattern"), py::arg("centres"), py::arg("patterns"),
           py::arg("segments"), py::arg("start_code"), py::arg("end_code"),
           "ValueError naming the first part that disagrees with the others")
      .def(py::init<const SequenceDescription&>(), py::arg("other"), "A copy of another sequence")
      .def_readonly("markers", &SequenceDescription::markers, "the marker family (MarkerSystem)")
      .def_property_readonly(
          "projector", [](const SequenceDescription& s) { return py::make_tuple(s.projector_width, s.projector_height); },
          "projector resolution (width, height)")
      .def_readonly("fps", &SequenceDescription::fps, "projector frame rate")
      .def_property_readonly(
          "grid", [](const SequenceDescription& s) { return py::make_tuple(s.grid_rows, s.grid_cols); },
          "markers per array as (rows, cols)")
      .def_readonly("arrays", &SequenceDescription::arrays)
      .def_readonly("markers_per_array", &SequenceDescription::markers_per_array)
      .def_property_readonly(
          "scales", [](const SequenceDescription& s) { return py::tuple(py::cast(s.scales)); },
          "the scale factors, in the order of the patterns' scale_index")
      .def_readonly("marker_px", &SequenceDescription::marker_px, "side of a marker at scale 1, border included")
      .def_readonly("margin_px", &SequenceDescription::margin_px, "image edge to the outermost centres of the layout")
      .def_readonly("snap_to_pixels", &SequenceDescription::snap_to_pixels)
      .def_readonly("min_gap_modules", &SequenceDescription::min_gap_modules)
      .def_readonly("frames_per_pattern", &SequenceDescription::frames_per_pattern)
      .def_property_readonly(
          "centres",
          [](const py::object& self) {
            const auto& s = self.cast<const SequenceDescription&>();
            return ReadOnlyView(reinterpret_cast<const double*>(s.centres.data()),
                                {s.arrays, s.markers_per_array, 2}, self);
          },
          "marker centres in projector pixels, (arrays, markers_per_array, 2), a read-only view")
      .def_readonly("patterns", &SequenceDescription::patterns, "every Pattern, in time order")
      .def_readonly("segments", &SequenceDescription::segments, "the Segments that tile the frames")
      .def_readonly("start_code", &SequenceDescription::start_code)
      .def_readonly("end_code", &SequenceDescription::end_code)
      .def_property_readonly("frame_count", &SequenceDescription::FrameCount)
      .def_property_readonly("duration_s", &SequenceDescription::DurationS)
      .def_property_readonly(
          "point_count", [](const SequenceDescription& s) { return s.arrays * s.markers_per_array; },
          "distinct MSM centres: arrays x markers per array")
      .def("segment_at", &SequenceDescription::SegmentAt, py::arg("frame"),
           "The Segment frame `frame` belongs to; IndexError outside the sequence")
      .def(
          "pattern_index_at",
          [](const SequenceDescription& s, int frame) -> py::object {
            const int index = s.PatternIndexAt(frame);
            return index < 0 ? py::none() : py::cast(index);
          },
          py::arg("frame"), "Index in patterns of the pattern shown at `frame`, or None; IndexError outside")
      .def(
          "markers_shown",
          [](const SequenceDescription& s, int index) {
            const std::vector<int> shown = s.MarkersShown(index);
            py::array_t<std::int64_t> out(static_cast<py::ssize_t>(shown.size()));
            std::copy(shown.begin(), shown.end(), out.mutable_data());
            return out;
          },
          py::arg("pattern_index"), "Marker indices (= ids) drawn in a pattern, ascending")
      .def(
          "save",
          [](const SequenceDescription& s, const std::filesystem::path& path) { formats::WriteSequence(path, s); },
          py::arg("path"),
           "Write sequence.json atomically; InputError naming the file for a sequence whose parts disagree")
      .def(py::self == py::self)
      .def("__repr__", [](const SequenceDescription& s) {
        return "Sequence(" + s.markers.spec + ", " + std::to_string(s.patterns.size()) + " patterns, " +
               std::to_string(s.FrameCount()) + " frames at " + formats::PythonFloat(s.fps) + " fps)";
      });
}

}  // namespace calibproj::bindings
