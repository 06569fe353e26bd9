// calibproj._core.ingest.CameraIngestResult: one camera's ingest (sync, statistics,
// per-scale records, merged centres, signals) as a bound class with typed attributes;
// per-record and per-centre values come as numpy columns.

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <optional>
#include <string>
#include <vector>

#include "calibproj/formats/detect_report.h"
#include "images.h"
#include "ingest_options.h"
#include "json_convert.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

using detect::MergedCentre;
using detect::ScaleRecord;

// One value of every element as a numpy column.
template <typename T, typename Item, typename Get>
py::array_t<T> Column(const std::vector<Item>& items, Get get) {
  py::array_t<T> out(static_cast<py::ssize_t>(items.size()));
  for (std::size_t i = 0; i < items.size(); ++i) out.mutable_data()[i] = get(items[i]);
  return out;
}

// (N, 2) points of every element.
template <typename Item, typename Get>
py::array_t<double> PointColumn(const std::vector<Item>& items, Get get) {
  py::array_t<double> out({static_cast<py::ssize_t>(items.size()), py::ssize_t{2}});
  for (std::size_t i = 0; i < items.size(); ++i) {
    const cv::Point2d p = get(items[i]);
    out.mutable_at(i, 0) = p.x;
    out.mutable_at(i, 1) = p.y;
  }
  return out;
}

py::array_t<double> CornerColumn(const std::vector<ScaleRecord>& records) {
  py::array_t<double> out({static_cast<py::ssize_t>(records.size()), py::ssize_t{4}, py::ssize_t{2}});
  for (std::size_t i = 0; i < records.size(); ++i) {
    for (int k = 0; k < 4; ++k) {
      out.mutable_at(i, k, 0) = records[i].corners[k].x;
      out.mutable_at(i, k, 1) = records[i].corners[k].y;
    }
  }
  return out;
}

// The per-scale detections of a camera, as columns.
struct ScaleRecords {
  std::vector<ScaleRecord> records;
};

// The merged MSM centres of a camera, as columns.
struct MergedCentres {
  std::vector<MergedCentre> centres;
};

void RegisterColumns(py::module_& m) {
  py::class_<ScaleRecords>(m, "ScaleRecords",
                           "Every marker detection of a camera, one per (pattern, array, marker, scale), as columns")
      .def("__len__", [](const ScaleRecords& r) { return r.records.size(); })
      .def_property_readonly("pattern", [](const ScaleRecords& r) { return Column<int>(r.records, [](const ScaleRecord& x) { return x.pattern; }); })
      .def_property_readonly("array", [](const ScaleRecords& r) { return Column<int>(r.records, [](const ScaleRecord& x) { return x.array; }); })
      .def_property_readonly("marker", [](const ScaleRecords& r) { return Column<int>(r.records, [](const ScaleRecord& x) { return x.marker; }); })
      .def_property_readonly("scale_index", [](const ScaleRecords& r) { return Column<int>(r.records, [](const ScaleRecord& x) { return x.scale_index; }); })
      .def_property_readonly("centre", [](const ScaleRecords& r) { return PointColumn(r.records, [](const ScaleRecord& x) { return x.centre; }); },
                             "(N, 2) undistorted pixels: the intersection of the undistorted diagonals")
      .def_property_readonly("corners", [](const ScaleRecords& r) { return CornerColumn(r.records); },
                             "(N, 4, 2) distorted image pixels, OpenCV order")
      .def_property_readonly("side_px", [](const ScaleRecords& r) { return Column<double>(r.records, [](const ScaleRecord& x) { return x.side_px; }); },
                             "mean side of the detected square, distorted pixels")
      .def_property_readonly("first_frame", [](const ScaleRecords& r) { return Column<int>(r.records, [](const ScaleRecord& x) { return x.first_frame; }); })
      .def_property_readonly("frame_count", [](const ScaleRecords& r) { return Column<int>(r.records, [](const ScaleRecord& x) { return x.frame_count; }); })
      .def_property_readonly("in_region", [](const ScaleRecords& r) { return Column<bool>(r.records, [](const ScaleRecord& x) { return x.in_region; }); },
                             "found by region-of-interest detection")
      .def_property_readonly("kept", [](const ScaleRecords& r) { return Column<bool>(r.records, [](const ScaleRecord& x) { return x.kept; }); },
                             "used in the merged centre")
      .def_property_readonly("deviation_px", [](const ScaleRecords& r) { return Column<double>(r.records, [](const ScaleRecord& x) { return x.deviation_px; }); },
                             "distance to the median of its MSM's scales");
  py::class_<MergedCentres>(m, "MergedCentres", "One centre per MSM of a camera, sorted by (array, marker), as columns")
      .def("__len__", [](const MergedCentres& c) { return c.centres.size(); })
      .def_property_readonly("array", [](const MergedCentres& c) { return Column<int>(c.centres, [](const MergedCentre& x) { return x.array; }); })
      .def_property_readonly("marker", [](const MergedCentres& c) { return Column<int>(c.centres, [](const MergedCentre& x) { return x.marker; }); })
      .def_property_readonly("xy", [](const MergedCentres& c) { return PointColumn(c.centres, [](const MergedCentre& x) { return x.centre; }); },
                             "(N, 2) undistorted pixels")
      .def_property_readonly("scales_kept", [](const MergedCentres& c) { return Column<int>(c.centres, [](const MergedCentre& x) { return x.scales_kept; }); })
      .def_property_readonly("scales_rejected", [](const MergedCentres& c) { return Column<int>(c.centres, [](const MergedCentre& x) { return x.scales_rejected; }); })
      .def_property_readonly("drift", [](const MergedCentres& c) { return PointColumn(c.centres, [](const MergedCentre& x) { return x.drift; }); },
                             "(N, 2) the move of each centre for its scales' drift (in xy; 0 where none)");
}

void RegisterStatistics(py::module_& m) {
  using ingest::ScaleStats;
  py::class_<ScaleStats>(m, "ScaleStats", "What became of the markers of one scale")
      .def(py::init<>(), "Nothing of this scale")
      .def_readonly("patterns", &ScaleStats::patterns, "patterns of this scale in the sequence")
      .def_readonly("detected_patterns", &ScaleStats::detected_patterns, "patterns whose frames went to detection")
      .def_readonly("skipped_patterns", &ScaleStats::skipped_patterns, "no marker resolvable or inside the image")
      .def_readonly("searched", &ScaleStats::searched, "markers searched")
      .def_readonly("too_small", &ScaleStats::too_small)
      .def_readonly("outside", &ScaleStats::outside)
      .def_readonly("folded", &ScaleStats::folded, "over the edge between two surfaces")
      .def_readonly("unresolvable", &ScaleStats::unresolvable, "of a size the camera was not decoding")
      .def_readonly("redundant", &ScaleStats::redundant, "left to larger scales of their MSM")
      .def_readonly("detected", &ScaleStats::detected, "markers found")
      .def_readonly("kept", &ScaleStats::kept, "used in merged centres")
      .def_property_readonly(
          "spread_px",
          [](const ScaleStats& s) -> std::optional<double> {
            if (s.spread_count == 0) return std::nullopt;
            return s.spread_px;
          },
          "RMS distance (undistorted px) of the kept detections from their MSM's merged centre, over MSMs kept "
          "at two scales or more; None when there were none")
      .def_readonly("spread_count", &ScaleStats::spread_count);
  using video::FrameClockStats;
  py::class_<FrameClockStats>(m, "FrameClockStats", "A video's frames on the frame grid")
      .def_readonly("frames", &FrameClockStats::frames, "frames placed")
      .def_readonly("dropped", &FrameClockStats::dropped, "empty slots between placed frames")
      .def_readonly("duplicated", &FrameClockStats::duplicated, "frames in a slot already taken: skipped")
      .def_readonly("untimed", &FrameClockStats::untimed, "frames without a timestamp")
      .def_readonly("largest_gap", &FrameClockStats::largest_gap, "most slots between two consecutive frames")
      .def_readonly("jitter_rms_s", &FrameClockStats::jitter_rms_s, "timing jitter, seconds");
  using detect::ScaleDriftResult;
  py::class_<ScaleDriftResult>(m, "ScaleDriftResult", "How a camera's centres were moved for their scales' drift")
      .def_readonly("bandwidth", &ScaleDriftResult::bandwidth,
                    "the kernel's width chosen, a share of the MSMs' extent (inf: one drift; 0: none)")
      .def_readonly("msms", &ScaleDriftResult::msms, "MSMs kept at two scales of different sizes")
      .def_readonly("corrected", &ScaleDriftResult::corrected, "centres moved")
      .def_readonly("rms_shift_px", &ScaleDriftResult::rms_shift_px, "root mean square of their moves")
      .def_readonly("disagreement_none", &ScaleDriftResult::disagreement_none,
                    "leave-one-out squared disagreement of the scales without a drift, px^2")
      .def_readonly("disagreement_chosen", &ScaleDriftResult::disagreement_chosen, "... with the drift chosen");
}

}  // namespace

py::object BoundIngestResult(const ingest::CameraIngestResult& result, const ingest::SequenceDescription& sequence) {
  IngestResult out;
  out.result = result;
  out.report = formats::CameraResultSummary(result, sequence);
  return py::cast(std::move(out));
}

void register_ingest_result(py::module_& m) {
  RegisterColumns(m);
  RegisterStatistics(m);
  using R = ingest::CameraIngestResult;
  const auto field = [](auto member) {
    return [member](const IngestResult& r) { return r.result.*member; };
  };
  py::class_<IngestResult>(m, "CameraIngestResult", "One camera's ingest: sync, statistics, detections, centres")
      .def(py::init<>(), "Nothing ingested (no frame, no detection)")
      .def_property_readonly(
          "report", [](const IngestResult& r) { return JsonToPython(r.report); },
          "the camera's entry of detect_report.json, built where calibproj-native builds it")
      .def_property_readonly("video", field(&R::video), "what the video's container says")
      .def_property_readonly("sync", field(&R::sync), "the frame map from the light codes")
      .def_property_readonly("timing", field(&R::timing), "frames on the frame grid")
      .def_property_readonly("frames_decoded", field(&R::frames_decoded))
      .def_property_readonly("frames_converted", field(&R::frames_converted),
                             "decoded frames whose grey image was made (to detect on)")
      .def_property_readonly("frames_detected", field(&R::frames_detected), "frames that went into a detection")
      .def_property_readonly("patterns_whole_frame", field(&R::patterns_whole_frame))
      .def_property_readonly("patterns_in_regions", field(&R::patterns_in_regions))
      .def_property_readonly("patterns_dropped", field(&R::patterns_dropped),
                             "frames not clean under the final frame map")
      .def_property_readonly("patterns_missing", field(&R::patterns_missing),
                             "not recorded (before the video starts or after it ends)")
      .def_property_readonly("detections_rejected", field(&R::detections_rejected),
                             "unexpected id, duplicate, or off the prediction")
      .def_property_readonly("markers_verified", field(&R::markers_verified),
                             "found at their predicted corners, without the detector")
      .def_property_readonly("detections_inconsistent", field(&R::detections_inconsistent),
                             "off the homographies of the others, or over a surface edge")
      .def_property_readonly(
          "consistency_problem",
          [](const IngestResult& r) -> std::optional<std::string> {
            if (r.result.consistency_problem.empty()) return std::nullopt;
            return r.result.consistency_problem;
          },
          "why no detection could be trusted; None when they could")
      .def_property_readonly("scales", field(&R::scales), "per scale of the sequence, its ScaleStats")
      .def_property_readonly(
          "records", [](const IngestResult& r) { return ScaleRecords{r.result.records}; }, "every detection")
      .def_property_readonly(
          "centres", [](const IngestResult& r) { return MergedCentres{r.result.centres}; }, "the merged centres")
      .def_property_readonly("scale_drift", field(&R::scale_drift), "how the centres were moved for their scales' drift")
      .def_property_readonly("signal", field(&R::signal),
                             "mean luma per grid slot, NaN where not measured or dropped")
      .def_property_readonly(
          "band_signals",
          [](const IngestResult& r) {
            const auto& bands = r.result.band_signals;
            py::array_t<double> out({static_cast<py::ssize_t>(bands.size()),
                                     static_cast<py::ssize_t>(r.result.signal.size())});
            for (std::size_t b = 0; b < bands.size(); ++b) {
              std::copy(bands[b].begin(), bands[b].end(), out.mutable_data(static_cast<py::ssize_t>(b), 0));
            }
            return out;
          },
          "(bands, slots): the signal per band of rows (the rolling-shutter readout)")
      .def_property_readonly("homography_valid", field(&R::homography_valid))
      .def_property_readonly(
          "homography",
          [](const IngestResult& r) {
            py::array_t<double> out({py::ssize_t{3}, py::ssize_t{3}});
            for (int i = 0; i < 9; ++i) out.mutable_data()[i] = r.result.homography(i / 3, i % 3);
            return out;
          },
          "projector pixels -> undistorted pixels")
      .def_property_readonly("homography_rms_px", field(&R::homography_rms_px))
      .def_property_readonly("seconds_total", field(&R::seconds_total))
      .def_property_readonly("seconds_detection", field(&R::seconds_detection),
                             "CPU time of the detection threads")
      .def_property_readonly(
          "thumbnail", [](const IngestResult& r) { return GrayArray(r.result.thumbnail); },
          "grey image of the thumbnail pattern; empty when thumbnail_width is 0")
      .def_property_readonly("thumbnail_pattern", field(&R::thumbnail_pattern), "the pattern the thumbnail shows");
}

}  // namespace calibproj::bindings
