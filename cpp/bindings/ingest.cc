// Bindings of calibproj::ingest: one camera's video to MSM centres. The sequence comes
// as the body of sequence.json (Sequence.to_dict()); results come back as numpy arrays.

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
#include "checks.h"
#include "ingest_options.h"
#include "json_convert.h"
#include "calibproj/video/video_reader.h"
#include "images.h"
#include "registry.h"
#include "sync_convert.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

// The body of sequence.json as Sequence.to_dict() gives it, read by the one reader of
// the format (the messages say "sequence: at patterns/0: ...").
ingest::SequenceDescription SequenceFromDict(const py::dict& d) {
  const nlohmann::json document = PythonToJson(d, "sequence");
  try {
    return formats::SequenceFromDocument(document);
  } catch (const std::invalid_argument& error) {
    throw std::invalid_argument(std::string("sequence: ") + error.what());
  }
}

ingest::CameraModel CameraFromArrays(const DoubleArray& K, const DoubleArray& dist,
                                     const std::optional<std::pair<int, int>>& resolution, const std::string& source) {
  RequireShape(K, {3, 3}, "K");
  RequireShape(dist, {-1}, "dist");
  ingest::CameraModel camera;
  for (int i = 0; i < 9; ++i) camera.lens.K(i / 3, i % 3) = K.data()[i];
  camera.lens.dist.assign(dist.data(), dist.data() + dist.size());
  if (resolution) {
    RequireCount(resolution->first, 1, limits::kMaxImageSide, "resolution width");
    RequireCount(resolution->second, 1, limits::kMaxImageSide, "resolution height");
    camera.resolution = cv::Size(resolution->first, resolution->second);
  }
  camera.source = source;
  camera.lens.Check();
  return camera;
}

template <typename T>
py::array_t<T> Column(const std::vector<detect::ScaleRecord>& records, T (*get)(const detect::ScaleRecord&)) {
  py::array_t<T> out(static_cast<py::ssize_t>(records.size()));
  for (std::size_t i = 0; i < records.size(); ++i) out.mutable_data()[i] = get(records[i]);
  return out;
}

py::dict RecordsDict(const std::vector<detect::ScaleRecord>& records) {
  using R = detect::ScaleRecord;
  const auto n = static_cast<py::ssize_t>(records.size());
  py::array_t<double> centre({n, py::ssize_t{2}}), corners({n, py::ssize_t{4}, py::ssize_t{2}});
  for (py::ssize_t i = 0; i < n; ++i) {
    centre.mutable_at(i, 0) = records[i].centre.x;
    centre.mutable_at(i, 1) = records[i].centre.y;
    for (int k = 0; k < 4; ++k) {
      corners.mutable_at(i, k, 0) = records[i].corners[k].x;
      corners.mutable_at(i, k, 1) = records[i].corners[k].y;
    }
  }
  py::dict d;
  d["pattern"] = Column<int>(records, [](const R& r) { return r.pattern; });
  d["array"] = Column<int>(records, [](const R& r) { return r.array; });
  d["marker"] = Column<int>(records, [](const R& r) { return r.marker; });
  d["scale_index"] = Column<int>(records, [](const R& r) { return r.scale_index; });
  d["centre"] = centre;
  d["corners"] = corners;
  d["side_px"] = Column<double>(records, [](const R& r) { return r.side_px; });
  d["first_frame"] = Column<int>(records, [](const R& r) { return r.first_frame; });
  d["frame_count"] = Column<int>(records, [](const R& r) { return r.frame_count; });
  d["in_region"] = Column<bool>(records, [](const R& r) { return r.in_region; });
  d["kept"] = Column<bool>(records, [](const R& r) { return r.kept; });
  d["deviation_px"] = Column<double>(records, [](const R& r) { return r.deviation_px; });
  return d;
}

py::dict CentresDict(const std::vector<detect::MergedCentre>& centres) {
  const auto n = static_cast<py::ssize_t>(centres.size());
  py::array_t<int> array(n), marker(n), kept(n), rejected(n);
  py::array_t<double> xy({n, py::ssize_t{2}});
  for (py::ssize_t i = 0; i < n; ++i) {
    array.mutable_at(i) = centres[i].array;
    marker.mutable_at(i) = centres[i].marker;
    kept.mutable_at(i) = centres[i].scales_kept;
    rejected.mutable_at(i) = centres[i].scales_rejected;
    xy.mutable_at(i, 0) = centres[i].centre.x;
    xy.mutable_at(i, 1) = centres[i].centre.y;
  }
  py::dict d;
  d["array"] = array;
  d["marker"] = marker;
  d["xy"] = xy;
  d["scales_kept"] = kept;
  d["scales_rejected"] = rejected;
  return d;
}

py::list ScalesList(const std::vector<ingest::ScaleStats>& scales) {
  py::list out;
  for (const auto& s : scales) {
    py::dict d;
    d["patterns"] = s.patterns;
    d["detected_patterns"] = s.detected_patterns;
    d["skipped_patterns"] = s.skipped_patterns;
    d["searched"] = s.searched;
    d["too_small"] = s.too_small;
    d["outside"] = s.outside;
    d["folded"] = s.folded;
    d["unresolvable"] = s.unresolvable;
    d["redundant"] = s.redundant;
    d["detected"] = s.detected;
    d["kept"] = s.kept;
    d["spread_px"] = s.spread_count > 0 ? py::object(py::float_(s.spread_px)) : py::object(py::none());
    d["spread_count"] = s.spread_count;
    out.append(d);
  }
  return out;
}


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
                         const DoubleArray& K, const DoubleArray& dist, int cells, double outward_fraction,
                         int passes) {
  const cv::Mat gray = GrayView(image);
  const detect::Quad quad = QuadFromArray(corners);
  const ingest::CameraModel camera = CameraFromArrays(K, dist, std::nullopt, "lens");
  detect::UndistortedEdgeOptions options;
  options.outward_fraction = outward_fraction;
  options.passes = passes;
  options.Check();
  std::optional<detect::Quad> refined;
  {
    py::gil_scoped_release release;
    const detect::LensTables tables(camera.lens, gray.size());
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

bool ShowsMarker(const py::array_t<uint8_t, py::array::c_style>& image, const DoubleArray& corners, const DoubleArray& K,
                 const DoubleArray& dist, const std::string& spec, int id, bool inverted) {
  const cv::Mat gray = GrayView(image);
  const detect::Quad quad = QuadFromArray(corners);
  const ingest::CameraModel camera = CameraFromArrays(K, dist, std::nullopt, "lens");
  const detect::MarkerFamily family = detect::ParseMarkerFamily(spec);
  const cv::Mat bits = detect::ProjectedCells(family, id, inverted);
  py::gil_scoped_release release;
  const detect::LensTables tables(camera.lens, gray.size());
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

py::dict IngestResultDict(const ingest::CameraIngestResult& r, const ingest::SequenceDescription& sequence) {
  py::dict d;
  // The camera's entry of detect_report.json, built where calibproj-native builds it
  // (JSON text: doubles written to 17 digits read back exactly).
  d["report"] = JsonToPython(formats::CameraResultSummary(r, sequence));
  d["video"] = py::dict(py::arg("path") = r.video.path, py::arg("width") = r.video.width,
                        py::arg("height") = r.video.height, py::arg("fps") = r.video.fps,
                        py::arg("declared_fps") = r.video.declared_fps, py::arg("timed") = r.video.timed,
                        py::arg("frame_count") = r.video.frame_count);
  d["timing"] = py::dict(py::arg("frames") = r.timing.frames, py::arg("dropped") = r.timing.dropped,
                         py::arg("duplicated") = r.timing.duplicated, py::arg("untimed") = r.timing.untimed,
                         py::arg("largest_gap") = r.timing.largest_gap,
                         py::arg("jitter_rms_s") = r.timing.jitter_rms_s);
  d["sync"] = SyncResultDict(r.sync);
  d["frames_decoded"] = r.frames_decoded;
  d["frames_converted"] = r.frames_converted;
  d["frames_detected"] = r.frames_detected;
  d["patterns_whole_frame"] = r.patterns_whole_frame;
  d["patterns_in_regions"] = r.patterns_in_regions;
  d["patterns_dropped"] = r.patterns_dropped;
  d["patterns_missing"] = r.patterns_missing;
  d["detections_rejected"] = r.detections_rejected;
  d["markers_verified"] = r.markers_verified;
  d["detections_inconsistent"] = r.detections_inconsistent;
  d["consistency_problem"] = r.consistency_problem.empty() ? py::object(py::none()) : py::cast(r.consistency_problem);
  d["scales"] = ScalesList(r.scales);
  d["records"] = RecordsDict(r.records);
  d["centres"] = CentresDict(r.centres);
  py::array_t<double> signal(static_cast<py::ssize_t>(r.signal.size()));
  std::copy(r.signal.begin(), r.signal.end(), signal.mutable_data());
  d["signal"] = signal;
  const py::ssize_t bands = static_cast<py::ssize_t>(r.band_signals.size());
  py::array_t<double> band_signals({bands, static_cast<py::ssize_t>(r.signal.size())});
  for (py::ssize_t b = 0; b < bands; ++b) {
    const auto& band = r.band_signals[b];
    std::copy(band.begin(), band.end(), band_signals.mutable_data(b, 0));
  }
  d["band_signals"] = band_signals;
  d["homography_valid"] = r.homography_valid;
  py::array_t<double> H({py::ssize_t{3}, py::ssize_t{3}});
  for (int i = 0; i < 9; ++i) H.mutable_data()[i] = r.homography(i / 3, i % 3);
  d["homography"] = H;
  d["homography_rms_px"] = r.homography_rms_px;
  d["seconds_total"] = r.seconds_total;
  d["seconds_detection"] = r.seconds_detection;
  d["thumbnail"] = GrayArray(r.thumbnail);
  d["thumbnail_pattern"] = r.thumbnail_pattern;
  return d;
}

py::array_t<double> MapWithTables(const DoubleArray& K, const DoubleArray& dist, std::pair<int, int> resolution,
                                  const DoubleArray& points, bool undistort) {
  RequireShape(points, {-1, 2}, "points");
  const ingest::CameraModel camera = CameraFromArrays(K, dist, std::nullopt, "lens");
  const detect::LensTables tables(camera.lens, cv::Size(resolution.first, resolution.second));
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
  m.def("lens_tables_map", &MapWithTables, py::arg("K"), py::arg("dist"), py::arg("resolution"), py::arg("points"),
        py::arg("undistort") = true,
        "Points (N, 2) undistorted (or distorted) through the interpolated lens tables the corner "
        "refinement uses.");
  m.def("refine_undistorted_corners", &RefineCorners, py::arg("image"), py::arg("corners"), py::arg("K"),
        py::arg("dist"), py::arg("cells"), py::arg("outward_fraction") = 0.45, py::arg("passes") = 6,
        "Undistorted corners (4, 2) of a marker `cells` modules wide detected at `corners` (distorted "
        "pixels) in a grey image, from straight edge lines fitted in undistorted pixels; None when an "
        "edge cannot be fitted.");
  m.def("shows_marker", &ShowsMarker, py::arg("image"), py::arg("corners"), py::arg("K"), py::arg("dist"),
        py::arg("spec"), py::arg("id"), py::arg("inverted") = false,
        "Whether a grey image shows marker `id` of family `spec` on the quad whose undistorted corners "
        "are `corners` (4, 2): every cell read through them on its expected side (the check that "
        "accepts a marker at its predicted place without the detector).");
  m.def("valid_known_exposure", &ingest::ValidKnownExposure, py::arg("seconds"),
        "Whether a camera's known exposure time (--exposure CAMERA=SECONDS) is one: 0 < seconds <= 1.");
  m.def("option_table", &IngestOptionTable,
        "Every ingest knob as {name, default, help}, in order: the one declaration "
        "calibproj.ingest_options.IngestOptions and both command lines are made from.");
  py::class_<ingest::SequenceDescription>(
      m, "Sequence",
      "A projection sequence as the core holds it: the body of sequence.json (Sequence.to_dict()) read and "
      "checked once by the format's one reader, then given to every camera's ingest_camera.")
      .def(py::init([](const py::dict& document) { return SequenceFromDict(document); }), py::arg("document"))
      .def_property_readonly("frame_count", &ingest::SequenceDescription::FrameCount)
      .def_readonly("arrays", &ingest::SequenceDescription::arrays)
      .def_readonly("markers_per_array", &ingest::SequenceDescription::markers_per_array)
      .def_readonly("markers", &ingest::SequenceDescription::markers, "marker family spec")
      .def_readonly("fps", &ingest::SequenceDescription::fps, "projector frame rate");
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
      [](const std::string& video, const ingest::SequenceDescription& description, const DoubleArray& K,
         const DoubleArray& dist,
         const std::optional<std::pair<int, int>>& resolution, const std::string& source,
         const detect::ArucoOptions& aruco, const detect::AprilTagOptions& apriltag,
         const std::optional<py::function>& progress, const std::optional<video::SourceOptions>& live,
         const py::kwargs& kwargs) {
        const ingest::CameraModel camera = CameraFromArrays(K, dist, resolution, source);
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
          result = ingest::IngestCamera(video, description, camera, options, callback, live.value_or(video::SourceOptions{}));
        }
        return IngestResultDict(result, description);
      },
      py::arg("video"), py::arg("sequence"), py::arg("K"), py::arg("dist"), py::arg("resolution"),
      py::arg("source"), py::arg("aruco"), py::arg("apriltag"), py::arg("progress") = py::none(),
      py::arg("live") = py::none(),
      "Synchronise one camera's video with the sequence (a Sequence) and detect its "
      "MSMs: sync, statistics, per-scale records and merged centres (undistorted pixels). "
      "`progress(decoded, total)` is called now and then. `live` (a video.SourceOptions): `video` "
      "is a stream or device, ingested as its frames arrive (and recorded where it says) until the "
      "end light code is in. Keyword options: see option_table().");
}

}  // namespace calibproj::bindings
