// calibproj._core.formats: the results files, the metric scale and the exports, written
// by the same C++ as calibproj-native. Conversions from the Python objects only.

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <filesystem>

#include "calibproj/formats/calibration.h"
#include "calibproj/formats/command_flags.h"
#include "calibproj/formats/detect_report.h"
#include "calibproj/formats/export.h"
#include "calibproj/formats/files.h"
#include "calibproj/formats/earlier_observations.h"
#include "calibproj/formats/intrinsics_file.h"
#include "calibproj/formats/scale.h"
#include "calibproj/formats/sequence_file.h"
#include "calibproj/formats/video_container.h"
#include "convert.h"
#include "python_objects.h"
#include "json_convert.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

using formats::Calibration;

// The Python object converted by `convert`; a missing attribute or key, or a value of
// the wrong type, becomes a TypeError naming `what`.
template <typename Convert>
auto Converted(const std::string& what, Convert&& convert) {
  try {
    return convert();
  } catch (py::error_already_set& error) {
    if (!error.matches(PyExc_AttributeError) && !error.matches(PyExc_KeyError) && !error.matches(PyExc_IndexError) &&
        !error.matches(PyExc_TypeError) && !error.matches(PyExc_ValueError)) {
      throw;
    }
    throw py::type_error(what + ": " + error.what());
  } catch (const py::cast_error& error) {
    throw py::type_error(what + ": " + error.what());
  }
}

// A bound ScaleMeasurement (TypeError for anything else).
const formats::ScaleMeasurement& MeasurementFrom(const py::object& m) {
  if (!py::isinstance<formats::ScaleMeasurement>(m)) {
    throw py::type_error("measurement: expected a ScaleMeasurement, got " +
                         std::string(Py_TYPE(m.ptr())->tp_name));
  }
  return m.cast<const formats::ScaleMeasurement&>();
}

void RegisterScaleTypes(py::module_& m) {
  using formats::ScaleMeasurement;
  py::class_<ScaleMeasurement>(m, "ScaleMeasurement", "One length measured in the room (a --scale value).")
      .def(py::init([](std::string kind, double metres, std::vector<std::string> cameras,
                       std::optional<std::pair<long long, long long>> marker, std::string text) {
             ScaleMeasurement measurement{std::move(kind), metres, std::move(cameras), marker, std::move(text)};
             measurement.Check();
             return measurement;
           }),
           py::arg("kind"), py::arg("metres"), py::arg("cameras") = std::vector<std::string>{},
           py::arg("marker") = py::none(), py::arg("text") = "",
           "ValueError unless kind, length, cameras and marker fit together")
      .def_readonly("kind", &ScaleMeasurement::kind, "camera-height, marker-size or distance")
      .def_readonly("metres", &ScaleMeasurement::metres, "the measured length")
      .def_property_readonly("cameras", [](const ScaleMeasurement& s) { return py::tuple(py::cast(s.cameras)); },
                             "the camera (camera-height) or the two cameras (distance)")
      .def_readonly("marker", &ScaleMeasurement::marker,
                    "(array, marker) of the marker measured (marker-size); None: the one nearest the centre of the "
                    "projected image")
      .def_readonly("text", &ScaleMeasurement::text, "the measurement as written, for messages")
      .def("__str__", &ScaleMeasurement::Label)
      .def("__repr__", [](const ScaleMeasurement& s) { return "ScaleMeasurement(" + s.Label() + ")"; });
  using formats::ScaleFit;
  py::class_<ScaleFit>(m, "ScaleFit", "What a scale measurement gives.")
      .def_readonly("metres_per_unit", &ScaleFit::metres_per_unit)
      .def_readonly("length", &ScaleFit::length, "the measured length in calibration units")
      .def_readonly("fitted_centres", &ScaleFit::fitted_centres,
                    "marker-size: MSM centres of the floor homography")
      .def_readonly("fit_rms", &ScaleFit::fit_rms, "marker-size: their RMS distance to it, calibration units");
}

// A bound ProjectedMarkers, or nothing for None (no sequence given).
std::optional<formats::ProjectedMarkers> MarkersFrom(const py::object& m) {
  if (m.is_none()) return std::nullopt;
  if (!py::isinstance<formats::ProjectedMarkers>(m)) {
    throw py::type_error("markers: expected a ProjectedMarkers, got " + std::string(Py_TYPE(m.ptr())->tp_name));
  }
  return m.cast<formats::ProjectedMarkers>();
}

// A ProjectedMarkers that must be given (TypeError for None).
formats::ProjectedMarkers RequiredMarkers(const py::object& markers) {
  auto projected = MarkersFrom(markers);
  if (!projected) throw py::type_error("markers: expected a ProjectedMarkers, got None");
  return *std::move(projected);
}

// The shape of an array as numpy prints it: (3, 2), (4,).
std::string ShapeText(const py::array& array) {
  std::string text = "(";
  for (py::ssize_t k = 0; k < array.ndim(); ++k) {
    text += (k ? ", " : "") + std::to_string(array.shape(k));
  }
  return text + (array.ndim() == 1 ? ",)" : ")");
}

using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;

formats::ProjectedMarkers NewMarkers(const DoubleArray& centres, double marker_side_px, std::pair<int, int> projector,
                                     const std::optional<DoubleArray>& largest) {
  if (centres.ndim() != 3 || centres.shape(2) != 2 || centres.size() == 0) {
    throw std::invalid_argument("MSM centres must have shape (arrays, markers, 2), got " + ShapeText(centres));
  }
  formats::ProjectedMarkers markers;
  markers.arrays = static_cast<int>(centres.shape(0));
  markers.markers_per_array = static_cast<int>(centres.shape(1));
  const double* values = centres.data();
  for (py::ssize_t k = 0; k + 1 < centres.size(); k += 2) markers.centres.emplace_back(values[k], values[k + 1]);
  markers.marker_side_px = marker_side_px;
  markers.projector_width = projector.first;
  markers.projector_height = projector.second;
  if (largest) {
    if (largest->ndim() != 2 || largest->shape(0) != centres.shape(0) || largest->shape(1) != centres.shape(1)) {
      throw std::invalid_argument("largest marker sides must have shape (" + std::to_string(centres.shape(0)) + ", " +
                                  std::to_string(centres.shape(1)) + "), got " + ShapeText(*largest));
    }
    markers.largest_side_px.assign(largest->data(), largest->data() + largest->size());
  }
  markers.Check();
  return markers;
}

void RegisterProjectedMarkers(py::module_& m) {
  using formats::ProjectedMarkers;
  py::class_<ProjectedMarkers>(
      m, "ProjectedMarkers",
      "Where the projector draws the MSMs: what the projector model and the marker-size scale need from the\n"
      "sequence. The MSM (array, marker) has point id array * markers_per_array + marker.")
      .def(py::init(&NewMarkers), py::arg("centres_px"), py::arg("marker_side_px"), py::arg("projector"),
           py::arg("largest_side_px") = py::none(),
           "centres_px: projector pixels of every MSM centre (arrays, markers_per_array, 2); marker_side_px: side\n"
           "of a marker at scale 1, border included; projector: (width, height); largest_side_px: per MSM\n"
           "(arrays, markers_per_array) the side of the largest marker drawn at it, NaN where none, or None\n"
           "when not known. ValueError for shapes or sizes that make no sense.")
      .def_static("from_sequence", &ProjectedMarkers::FromSequence, py::arg("sequence"),
                  "The MSMs a Sequence draws, with per MSM the side of the largest marker drawn at it (NaN "
                  "where none)")
      .def_property_readonly(
          "centres_px",
          [](const ProjectedMarkers& p) {
            py::array_t<double> out({static_cast<py::ssize_t>(p.arrays), static_cast<py::ssize_t>(p.markers_per_array),
                                     static_cast<py::ssize_t>(2)});
            double* values = out.mutable_data();
            for (const cv::Point2d& centre : p.centres) {
              *values++ = centre.x;
              *values++ = centre.y;
            }
            return out;
          },
          "(arrays, markers_per_array, 2) projector pixels")
      .def_readonly("marker_side_px", &ProjectedMarkers::marker_side_px)
      .def_property_readonly("projector",
                             [](const ProjectedMarkers& p) { return py::make_tuple(p.projector_width, p.projector_height); },
                             "(width, height)")
      .def_property_readonly(
          "largest_side_px",
          [](const ProjectedMarkers& p) -> py::object {
            if (p.largest_side_px.empty()) return py::none();
            py::array_t<double> out({static_cast<py::ssize_t>(p.arrays), static_cast<py::ssize_t>(p.markers_per_array)});
            std::copy(p.largest_side_px.begin(), p.largest_side_px.end(), out.mutable_data());
            return out;
          },
          "(arrays, markers_per_array), NaN where no marker is drawn; None when not known")
      .def_readonly("arrays", &ProjectedMarkers::arrays)
      .def_readonly("markers_per_array", &ProjectedMarkers::markers_per_array)
      .def_property_readonly("point_count", [](const ProjectedMarkers& p) { return p.centres.size(); })
      .def("pixels", &ProjectedMarkers::PixelsOf, py::arg("point_ids"),
           "Per point id its projector pixel (N, 2), NaN for an id beyond the sequence's MSMs")
      .def("largest_sides", &ProjectedMarkers::LargestSidesOf, py::arg("point_ids"),
           "Per point id the side of the largest marker drawn at it (projector px), NaN where not known")
      .def(
          "image_centre",
          [](const ProjectedMarkers& p) {
            // Pixel centres on integers.
            return Eigen::Vector2d((p.projector_width - 1) / 2.0, (p.projector_height - 1) / 2.0);
          },
          "The projector image's centre (pixels)");
}

}  // namespace

void register_formats(py::module_& m) {
  // A bad input file: the message names the file and the problem.
  py::register_exception<formats::InputError>(m, "InputError", PyExc_ValueError);
  py::register_exception_translator([](std::exception_ptr error) {
    try {
      if (error) std::rethrow_exception(error);
    } catch (const std::filesystem::filesystem_error& e) {  // OSError(errno, message, file), as open() raises
      const py::object os_error = py::reinterpret_borrow<py::object>(PyExc_OSError);
      PyErr_SetObject(PyExc_OSError, os_error(e.code().value(), e.code().message(), e.path1().string()).ptr());
    }
  });
  register_output_folder(m);
  register_provenance(m);
  register_tracks(m);
  register_camera_intrinsics(m);
  register_calibration(m);
  RegisterProjectedMarkers(m);
  RegisterScaleTypes(m);
  m.def("read_calibration", &formats::ReadCalibration, py::arg("directory"),
        "The Calibration of a results folder (camera_poses.json, metrics.json, points.ply); InputError naming "
        "the file and the problem");
  m.attr("calibration_files") = formats::kCalibrationFiles;
  m.attr("export_formats") = formats::kExportFormats;
  m.attr("default_marker_radius_sides") = formats::kDefaultMarkerRadiusSides;
  m.attr("min_marker_neighbours") = formats::kMinMarkerNeighbours;
  m.def(
      "write_calibration",
      [](const std::filesystem::path& directory, const py::object& calibration) {
        formats::WriteCalibration(directory, CalibrationFromPython(calibration));
      },
      py::arg("directory"), py::arg("calibration"),
      "camera_poses.json, metrics.json and points.ply of a Calibration, each written atomically");
  py::class_<formats::CommandFlag>(m, "CommandFlag", "A command-line flag that calibproj and calibproj-native both take.")
      .def_readonly("command", &formats::CommandFlag::command)
      .def_readonly("name", &formats::CommandFlag::name)
      .def_readonly("metavar", &formats::CommandFlag::metavar, "empty for a switch")
      .def_readonly("help", &formats::CommandFlag::help);
  m.def("command_flags", &formats::SharedCommandFlags,
        "Every flag both tools take, by command: the one declaration of their names and help texts");
  m.def("command_flag", &formats::SharedFlag, py::arg("command"), py::arg("name"),
        "The flag `name` of `command`; ValueError when both tools do not take it");
  m.def(
      "read_intrinsics",
      [](const std::filesystem::path& path, const std::string& name) {
        return formats::ReadIntrinsics(path, name);
      },
      py::arg("path"), py::arg("name") = "",
      "The CameraIntrinsics of a file in any supported format (name: the file stem when empty); "
      "InputError naming the file and the problem");
  m.def(
      "write_intrinsics",
      [](const std::filesystem::path& out, const formats::CameraIntrinsics& intrinsics, const py::object& extra) {
        nlohmann::ordered_json entries = nlohmann::ordered_json::object();
        if (!extra.is_none()) {
          if (!py::isinstance<py::dict>(extra)) throw py::type_error("extra: expected a dict or None");
          entries = PythonToJson<nlohmann::ordered_json>(extra, "extra");
        }
        formats::WriteIntrinsics(out, intrinsics, entries);
      },
      py::arg("out"), py::arg("intrinsics"), py::arg("extra") = py::none(),
      "Our intrinsics file of an Intrinsics, written atomically; extra: a dict whose entries follow the "
      "format's own (how they were measured, their uncertainty)");
  m.def(
      "intrinsics_from_json",
      [](const py::object& document, const std::string& name) {
        return formats::IntrinsicsFromDocument(PythonToJson(document, "document"), name);
      },
      py::arg("document"), py::arg("name"),
      "The CameraIntrinsics of our format's body (a dict, as json.load gives it); ValueError with the problem");
  m.def("intrinsics_files", &formats::IntrinsicsFilesIn, py::arg("directory"),
        "Camera name -> its intrinsics files in the folder (.json, .yaml, .yml, .xml; sorted); InputError when "
        "the folder does not exist or holds none");
  m.def("video_container", &formats::VideoContainerOfFile, py::arg("path"),
        "The video container the file's first bytes show ('MP4/MOV', 'Matroska/WebM', 'AVI', 'MPEG-TS', "
        "'MPEG-PS'), or '' for anything else (or a file that cannot be read)");
  m.def("intrinsics_file", &formats::IntrinsicsFileOf, py::arg("directory"), py::arg("name"),
        "The one intrinsics file of camera `name` in the folder; InputError naming the missing or second file");
  m.def("detect_report_path", &formats::DetectReportPath, py::arg("tracks"),
        "The detect report beside a tracks file: detect_report.json for tracks.json, NAME.detect_report.json "
        "for any other NAME.json");
  m.def(
      "read_sequence",
      &formats::ReadSequence, py::arg("path"),
      "The Sequence a sequence.json holds (the one reader of the format); InputError "
      "naming the file and the problem");
  m.def(
      "with_earlier_observations",
      [](const std::filesystem::path& earlier, const formats::Tracks& tracks, const py::dict& intrinsics) {
        const auto cameras = IntrinsicsFromPython(intrinsics);
        return formats::WithEarlierObservations(earlier, tracks, cameras);
      },
      py::arg("earlier"), py::arg("tracks"), py::arg("intrinsics"),
      "The Tracks `tracks` with the observations of an earlier results folder (or tracks.json) "
      "added; InputError naming the file (other intrinsics, shared point ids)");
  m.def(
      "scaled",
      [](const py::object& calibration, double factor) {
        return formats::Scaled(CalibrationFromPython(calibration), factor);
      },
      py::arg("calibration"), py::arg("factor"),
      "The calibration with every length multiplied by factor, in metres");
  m.def(
      "parse_scale", &formats::ParseScale, py::arg("text"),
      "A --scale value as a ScaleMeasurement; ValueError naming the bad part");
  m.def(
      "check_measurement",
      [](const py::object& measurement, const std::vector<std::string>& names, const py::object& markers) {
        const auto projected = MarkersFrom(markers);
        formats::CheckMeasurement(MeasurementFrom(measurement), names,
                                  projected ? &*projected : nullptr);
      },
      py::arg("measurement"), py::arg("camera_names"), py::arg("markers"));
  m.def(
      "scale_factor",
      [](const py::object& calibration, const py::object& measurement, const py::object& markers,
         double radius_sides) {
        const auto projected = MarkersFrom(markers);
        return formats::ScaleFactor(CalibrationFromPython(calibration),
                                    MeasurementFrom(measurement), projected ? &*projected : nullptr, radius_sides);
      },
      py::arg("calibration"), py::arg("measurement"), py::arg("markers"), py::arg("radius_sides"));
  m.def("parse_export_formats", &formats::ParseExportFormats, py::arg("text"));
  m.def(
      "colmap_camera",
      [](const formats::CameraIntrinsics& intrinsics) { return formats::ColmapCamera(intrinsics); },
      py::arg("intrinsics"), "(COLMAP model, parameters) of an Intrinsics");
  m.def("quaternion_wxyz", &formats::QuaternionWxyz, py::arg("R"), "Unit quaternion (w, x, y, z), w >= 0");
  m.def(
      "export",
      [](const py::object& calibration, const std::string& format, const std::filesystem::path& directory,
         const py::dict& intrinsics, const formats::Tracks* tracks) {
        std::vector<std::string> warnings;
        const auto files = formats::Export(CalibrationFromPython(calibration),
                                           format, directory,
                                           IntrinsicsFromPython(intrinsics),
                                           tracks, &warnings);
        return py::make_tuple(files, warnings);
      },
      py::arg("calibration"), py::arg("format"), py::arg("directory"), py::arg("intrinsics"), py::arg("tracks"),
      "(files written, warnings)");
}

}  // namespace calibproj::bindings
