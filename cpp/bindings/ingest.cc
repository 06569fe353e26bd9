// Bindings of calibproj::ingest: one camera's video to MSM centres. The sequence is a
// bound Sequence (sequence.cc); results come back as numpy arrays.

#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <optional>
#include <string>
#include <vector>

#include "calibproj/detect/marker_verification.h"
#include "calibproj/formats/detect_report.h"
#include "calibproj/formats/sequence_file.h"
#include "calibproj/ingest/camera_ingest.h"
#include "calibproj/ingest/option_table.h"
#include "checks.h"
#include "ingest_options.h"
#include "calibproj/video/video_reader.h"
#include "images.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

// A grey image array as an OpenCV image sharing its pixels.
cv::Mat GrayView(const py::array_t<uint8_t, py::array::c_style>& image) {
  RequireShape(image, {-1, -1}, "image");
  if (image.size() == 0) throw std::invalid_argument("image is empty");
  return cv::Mat(static_cast<int>(image.shape(0)), static_cast<int>(image.shape(1)), CV_8UC1,
                 const_cast<uint8_t*>(image.data()));
}

detect::Quad QuadFromArray(const DoubleArray& corners) {
  RequireShape(corners, {4, 2}, "corners");
  detect::Quad quad;
  for (int k = 0; k < 4; ++k) quad[k] = cv::Point2d(corners.data()[2 * k], corners.data()[2 * k + 1]);
  return quad;
}

py::object RefineCorners(const py::array_t<uint8_t, py::array::c_style>& image, const DoubleArray& corners,
                         const formats::CameraIntrinsics& intrinsics, int cells, double outward_fraction,
                         int passes) {
  const cv::Mat gray = GrayView(image);
  const detect::Quad quad = QuadFromArray(corners);
  detect::CheckLens(intrinsics);
  detect::UndistortedEdgeOptions options;
  options.outward_fraction = outward_fraction;
  options.passes = passes;
  options.Check();
  std::optional<detect::Quad> refined;
  {
    py::gil_scoped_release release;
    const detect::LensTables tables(intrinsics, gray.size());
    refined = detect::RefineUndistortedCorners(gray, cv::Point(0, 0), tables, cells, quad, options);
  }
  if (!refined) return py::none();
  py::array_t<double> out({py::ssize_t{4}, py::ssize_t{2}});
  for (int k = 0; k < 4; ++k) {
    out.mutable_at(k, 0) = (*refined)[k].x;
    out.mutable_at(k, 1) = (*refined)[k].y;
  }
  return out;
}

bool ShowsMarker(const py::array_t<uint8_t, py::array::c_style>& image, const DoubleArray& corners,
                 const formats::CameraIntrinsics& intrinsics, const std::string& spec, int id, bool inverted) {
  const cv::Mat gray = GrayView(image);
  const detect::Quad quad = QuadFromArray(corners);
  detect::CheckLens(intrinsics);
  const detect::MarkerFamily family = detect::ParseMarkerFamily(spec);
  const cv::Mat bits = detect::ProjectedCells(family, id, inverted);
  py::gil_scoped_release release;
  const detect::LensTables tables(intrinsics, gray.size());
  return detect::ShowsMarker(gray, cv::Point(0, 0), tables, quad, bits, detect::GetMarkerGeometry(family).quad_cells,
                             detect::VerificationOptions{});
}

}  // namespace

ingest::IngestOptions IngestOptionsFromKwargs(const detect::ArucoOptions& aruco, const detect::AprilTagOptions& apriltag,
                                              const py::kwargs& kwargs) {
  ingest::IngestOptions options;
  options.detector = {aruco, apriltag};
  for (const auto& item : kwargs) {
    const std::string key = py::str(item.first);
    if (!SetIngestOption(&options, key, item.second)) ThrowUnknownOption("ingest", key, IngestOptionTable());
  }
  return options;
}

py::array_t<double> MapWithTables(const formats::CameraIntrinsics& intrinsics, std::pair<int, int> resolution,
                                  const DoubleArray& points, bool undistort) {
  RequireShape(points, {-1, 2}, "points");
  detect::CheckLens(intrinsics);
  const detect::LensTables tables(intrinsics, cv::Size(resolution.first, resolution.second));
  std::vector<cv::Point2d> in;
  for (py::ssize_t i = 0; i < points.shape(0); ++i) in.emplace_back(points.at(i, 0), points.at(i, 1));
  const auto out = undistort ? tables.Undistort(in) : tables.Distort(in);
  py::array_t<double> result({points.shape(0), py::ssize_t{2}});
  for (std::size_t i = 0; i < out.size(); ++i) {
    result.mutable_at(i, 0) = out[i].x;
    result.mutable_at(i, 1) = out[i].y;
  }
  return result;
}

void register_ingest(py::module_& m) {
  register_sequence(m);
  register_ingest_result(m);
  m.def("lens_tables_map", &MapWithTables, py::arg("intrinsics"), py::arg("resolution"), py::arg("points"),
        py::arg("undistort") = true,
        "Points (N, 2) undistorted (or distorted) through the interpolated lens tables the corner "
        "refinement uses.");
  m.def("refine_undistorted_corners", &RefineCorners, py::arg("image"), py::arg("corners"), py::arg("intrinsics"),
        py::arg("cells"), py::arg("outward_fraction") = 0.45, py::arg("passes") = 6,
        "Undistorted corners (4, 2) of a marker `cells` modules wide detected at `corners` (distorted "
        "pixels) in a grey image, from straight edge lines fitted in undistorted pixels; None when an "
        "edge cannot be fitted.");
  m.def("shows_marker", &ShowsMarker, py::arg("image"), py::arg("corners"), py::arg("intrinsics"),
        py::arg("spec"), py::arg("id"), py::arg("inverted") = false,
        "Whether a grey image shows marker `id` of family `spec` on the quad whose undistorted corners "
        "are `corners` (4, 2): every cell read through them on its expected side (the check that "
        "accepts a marker at its predicted place without the detector).");
  m.def(
      "check_options",
      [](const detect::ArucoOptions& aruco, const detect::AprilTagOptions& apriltag, const py::kwargs& kwargs) {
        IngestOptionsFromKwargs(aruco, apriltag, kwargs).Check();
      },
      py::arg("aruco"), py::arg("apriltag"),
      "ValueError naming the first bad ingest option (keyword options as ingest_camera takes them), so that "
      "bad options stop an ingest before any camera, as calibproj-native's do.");
  m.def("shared_decode_threads", &ingest::SharedDecodeThreads, py::arg("decode_threads"), py::arg("cameras_at_once"),
        "FFmpeg's decoding threads for each of `cameras_at_once` cameras ingested together: `decode_threads` "
        "when set, else the machine's cores shared among them (all but one for one camera).");
  m.def("valid_known_exposure", &ingest::ValidKnownExposure, py::arg("seconds"),
        "Whether a camera's known exposure time (--exposure CAMERA=SECONDS) is one: 0 < seconds <= 1.");
  m.def(
      "unrefined_lens_changes",
      [] {
        // The knobs where OptionsForUnrefinedLenses differs from the defaults, in table order.
        const std::vector<Knob> defaults = IngestOptionTable();
        std::vector<std::pair<std::string, py::object>> changes;
        ingest::IngestOptions relaxed = ingest::OptionsForUnrefinedLenses();
        size_t k = 0;
        ingest::VisitIngestOptions(relaxed, [&](const char* name, const auto& field, const char*) {
          const py::object value = py::cast(field);
          if (!value.equal(defaults.at(k++).default_value)) changes.emplace_back(name, value);
        });
        return changes;
      },
      "(name, value) of the ingest knobs a calibration that refines lenses changes when no ingest options are "
      "given: the local consistency check off (a lens still to be refined does not allow its fraction of a "
      "pixel) and the scale drift off (its scales disagree by the lens's error).");
  m.def("option_table", &IngestOptionTable,
        "Every ingest knob as a Knob (name, default, help), in order: the one declaration "
        "calibproj.ingest.options.IngestOptions and both command lines are made from.");
  m.def(
      "light_levels",
      [](const ingest::SequenceDescription& sequence) {
        const sync::LightTimeline timeline = sequence.LightLevels();
        py::array_t<double> out(timeline.frame_count());
        for (int k = 0; k < timeline.frame_count(); ++k) out.mutable_data()[k] = timeline.Level(k);
        return out;
      },
      py::arg("sequence"), "Projector level of every sequence frame (1 white, 0 black, NaN for patterns).");
  m.def(
      "ingest_camera",
      [](const std::string& video, const ingest::SequenceDescription& description,
         const formats::CameraIntrinsics& intrinsics, const std::string& source,
         const detect::ArucoOptions& aruco, const detect::AprilTagOptions& apriltag,
         const std::optional<py::function>& progress, const std::optional<video::SourceOptions>& live,
         const py::kwargs& kwargs) {
        const ingest::IngestOptions options = IngestOptionsFromKwargs(aruco, apriltag, kwargs);
        ingest::ProgressCallback callback;
        if (progress) {
          callback = [function = *progress](int decoded, int total) {
            py::gil_scoped_acquire acquire;
            function(decoded, total);
          };
        }
        ingest::CameraIngestResult result;
        {
          py::gil_scoped_release release;
          result = ingest::IngestCamera(video, description, intrinsics, source, options, callback,
                                        live.value_or(video::SourceOptions{}));
        }
        return BoundIngestResult(result, description);
      },
      py::arg("video"), py::arg("sequence"), py::arg("intrinsics"), py::arg("source"), py::arg("aruco"), py::arg("apriltag"), py::arg("progress") = py::none(),
      py::arg("live") = py::none(),
      "Synchronise one camera's video with the sequence (a Sequence) and detect its "
      "MSMs with its intrinsics (an Intrinsics; source: where they come from): a CameraIngestResult (sync, "
      "statistics, per-scale records and merged centres in undistorted pixels). "
      "`progress(decoded, total)` is called now and then. `live` (a video.SourceOptions): `video` "
      "is a stream or device, ingested as its frames arrive (and recorded where it says) until the "
      "end light code is in. Keyword options: see option_table().");
}

}  // namespace calibproj::bindings
