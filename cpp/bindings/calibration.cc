// calibproj._core.formats.Calibration: the result of a calibration as the package's one
// Calibration class (calibproj.formats.calibration.Calibration), with its CameraPose,
// CameraMetrics and Plane. Values, like the dataclasses they replace: an attribute read
// gives a copy, an attribute set replaces it, `replace` gives a changed copy.

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "calibproj/formats/calibration.h"
#include "calibproj/formats/files.h"
#include "convert.h"
#include "python_objects.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

using formats::CameraMetrics;
using formats::CameraPose;
using formats::Calibration;
using formats::NamedText;
using formats::Plane;
using registration::PoseUncertainty;

// `convert()`, a value of the wrong type becoming a TypeError naming the attribute.
template <typename Convert>
auto Attribute(const char* owner, const char* name, Convert&& convert) {
  try {
    return convert();
  } catch (const py::cast_error& error) {
    throw py::type_error(std::string(owner) + "." + name + ": " + error.what());
  }
}

// A read-only copy: changing it cannot be mistaken for changing the calibration.
template <typename T>
py::array ReadOnly(const T& value) {
  py::array array = py::cast(value);
  py::detail::array_proxy(array.ptr())->flags &= ~py::detail::npy_api::NPY_ARRAY_WRITEABLE_;
  return array;
}

// {camera: (R, t)} in registration order.
py::dict PosesOf(const std::vector<CameraPose>& poses) {
  py::dict out;
  for (const CameraPose& pose : poses) {
    out[py::str(pose.name)] = py::make_tuple(ReadOnly(pose.R), ReadOnly(pose.t));
  }
  return out;
}

// owner: the class whose attribute it is, for the message.
std::vector<CameraPose> PosesFrom(const char* owner, const py::dict& poses) {
  return Attribute(owner, "poses", [&] {
    std::vector<CameraPose> out;
    for (const auto& [name, pose] : poses) {
      const auto R_t = pose.cast<std::pair<Eigen::Matrix3d, Eigen::Vector3d>>();
      out.push_back({name.cast<std::string>(), R_t.first, R_t.second});
    }
    return out;
  });
}

void SetPoses(Calibration& c, const py::dict& poses) { c.poses = PosesFrom("Calibration", poses); }

std::vector<std::string> NamesOf(const std::vector<CameraPose>& poses) {
  std::vector<std::string> names;
  for (const CameraPose& pose : poses) names.push_back(pose.name);
  return names;
}

py::dict FailedOf(const std::vector<NamedText>& failed) {
  py::dict out;
  for (const auto& [name, reason] : failed) out[py::str(name)] = reason;
  return out;
}

std::vector<NamedText> NamedTexts(const char* owner, const char* what, const py::dict& texts) {
  return Attribute(owner, what, [&] {
    std::vector<NamedText> out;
    for (const auto& [name, text] : texts) out.emplace_back(name.cast<std::string>(), text.cast<std::string>());
    return out;
  });
}

py::dict MetricsOf(const Calibration& c) {
  py::dict out;
  for (const auto& [name, metrics] : c.metrics) out[py::str(name)] = metrics;
  return out;
}

void SetMetrics(Calibration& c, const py::dict& metrics) {
  c.metrics = Attribute("Calibration", "metrics", [&] {
    std::vector<std::pair<std::string, CameraMetrics>> out;
    for (const auto& [name, m] : metrics) out.emplace_back(name.cast<std::string>(), m.cast<CameraMetrics>());
    return out;
  });
}

void SetPoints(Calibration& c, const RowMatrix& points) {
  c.points = RowsOf<formats::PointRows>(points, 3, "Calibration.points");
}

py::object UncertaintyOf(const Calibration& c) {
  return c.uncertainty.empty() ? py::none() : py::cast(c.uncertainty);
}

void SetUncertainty(Calibration& c, const std::optional<PoseUncertainty>& uncertainty) {
  c.uncertainty = uncertainty.value_or(PoseUncertainty{});
}

Calibration NewCalibration(const py::dict& poses, const py::dict& failed, const py::dict& metrics,
                           const RowMatrix& points, const std::vector<std::int64_t>& point_ids, std::string unit,
                           std::string model, std::vector<std::string> registration_order, double floor_rms,
                           std::vector<Plane> planes, const std::optional<PoseUncertainty>& uncertainty) {
  Calibration c;
  SetPoses(c, poses);
  c.failed = NamedTexts("Calibration", "failed", failed);
  SetMetrics(c, metrics);
  SetPoints(c, points);
  c.point_ids = point_ids;
  c.unit = std::move(unit);
  c.model = std::move(model);
  c.registration_order = std::move(registration_order);
  c.floor_rms = floor_rms;
  c.planes = std::move(planes);
  SetUncertainty(c, uncertainty);
  c.Check();
  return c;
}

const CameraPose& RegisteredPose(const Calibration& c, const std::string& name) {
  const CameraPose* pose = c.PoseOf(name);
  if (pose == nullptr) throw std::invalid_argument("camera " + name + ": not registered in this calibration");
  return *pose;
}

Calibration Load(const std::filesystem::path& directory) {
  if (!std::filesystem::is_directory(directory)) {
    throw formats::InputError(directory.string() + ": no such results folder");
  }
  return formats::ReadCalibration(directory);
}

py::tuple MetricsState(const CameraMetrics& m) {
  return py::make_tuple(m.mean_px, m.std_px, m.observations, m.inliers, m.track2_observations, m.view_score,
                        m.failure, m.rotation_sigma_deg, m.centre_sigma, m.weak);
}

CameraMetrics NewMetrics(std::optional<double> mean_px, std::optional<double> std_px, std::int64_t observations,
                         std::int64_t inliers, std::int64_t track2_observations, std::int64_t view_score,
                         std::optional<std::string> failure, std::optional<double> rotation_sigma_deg,
                         std::optional<double> centre_sigma, bool weak) {
  const auto check = [](const char* name, std::optional<double> value) {
    if (value && !(std::isfinite(*value) && *value >= 0.0)) {
      throw std::invalid_argument(std::string("CameraMetrics.") + name + ": must be >= 0 and finite, got " +
                                  formats::PythonFloat(*value));
    }
  };
  check("mean_px", mean_px);
  check("std_px", std_px);
  check("rotation_sigma_deg", rotation_sigma_deg);
  check("centre_sigma", centre_sigma);
  for (const std::int64_t count : {observations, inliers, track2_observations, view_score}) {
    if (count < 0) throw std::invalid_argument("CameraMetrics: counts must be >= 0, got " + std::to_string(count));
  }
  return CameraMetrics{mean_px, std_px, observations, inliers, track2_observations, view_score, std::move(failure),
                       rotation_sigma_deg, centre_sigma, weak};
}

void RegisterParts(py::module_& m) {
  py::class_<CameraPose>(m, "CameraPose", "A registered camera's pose in the floor frame: x_cam = R X + t.")
      .def_readonly("name", &CameraPose::name)
      .def_readonly("R", &CameraPose::R)
      .def_readonly("t", &CameraPose::t)
      .def_property_readonly("centre", &CameraPose::Centre, "the camera centre -R^T t");
  py::class_<CameraMetrics>(m, "CameraMetrics", "Per-camera figures of a calibration (pixels are undistorted pixels).")
      .def(py::init(&NewMetrics), py::arg("mean_px"), py::arg("std_px"), py::arg("observations"), py::arg("inliers"),
           py::arg("track2_observations"), py::arg("view_score"), py::arg("failure") = py::none(),
           py::arg("rotation_sigma_deg") = py::none(), py::arg("centre_sigma") = py::none(), py::arg("weak") = false)
      .def_readonly("mean_px", &CameraMetrics::mean_px, "mean reprojection error of the inlier observations")
      .def_readonly("std_px", &CameraMetrics::std_px)
      .def_readonly("observations", &CameraMetrics::observations, "observations of this camera in the tracks")
      .def_readonly("inliers", &CameraMetrics::inliers, "observations kept by the outlier filter")
      .def_readonly("track2_observations", &CameraMetrics::track2_observations,
                     "inliers whose point at least two registered cameras see")
      .def_readonly("view_score", &CameraMetrics::view_score, "view score (visibility pyramid) of its observations")
      .def_readonly("failure", &CameraMetrics::failure)
      .def_readonly("rotation_sigma_deg", &CameraMetrics::rotation_sigma_deg,
                     "1 sigma along the worst direction, from the final bundle adjustment's covariance, relative "
                     "to the first camera of the registration (0 for it); None when unknown")
      .def_readonly("centre_sigma", &CameraMetrics::centre_sigma, "in the calibration's unit; None when unknown")
      .def_readwrite("weak", &CameraMetrics::weak, "rotation known worse than the registration's limit")
      .def("__eq__", [](const CameraMetrics& a, const CameraMetrics& b) {
        return MetricsState(a).equal(MetricsState(b));
      })
      .def("__repr__", [](const CameraMetrics& metrics) {
        return "CameraMetrics" + std::string(py::repr(MetricsState(metrics)));
      })
      .def(py::pickle(&MetricsState, [](const py::tuple& state) {
        if (state.size() != 10) throw std::invalid_argument("CameraMetrics: not a pickled CameraMetrics");
        return NewMetrics(state[0].cast<std::optional<double>>(), state[1].cast<std::optional<double>>(),
                          state[2].cast<std::int64_t>(), state[3].cast<std::int64_t>(), state[4].cast<std::int64_t>(),
                          state[5].cast<std::int64_t>(), state[6].cast<std::optional<std::string>>(),
                          state[7].cast<std::optional<double>>(), state[8].cast<std::optional<double>>(),
                          state[9].cast<bool>());
      }));
  py::class_<Plane>(m, "Plane", "A plane besides the floor (a table top): normal . X = offset in the floor frame.")
      .def(py::init([](const Eigen::Vector3d& normal, double offset, std::int64_t points) {
             return Plane{normal, offset, points};
           }),
           py::arg("normal"), py::arg("offset"), py::arg("points") = 0)
      .def_readonly("normal", &Plane::normal)
      .def_readonly("offset", &Plane::offset)
      .def_readonly("points", &Plane::points, "the calibration's points on it")
      .def(py::pickle([](const Plane& p) { return py::make_tuple(p.normal, p.offset, p.points); },
                      [](const py::tuple& state) {
                        if (state.size() != 3) throw std::invalid_argument("Plane: not a pickled Plane");
                        return Plane{state[0].cast<Eigen::Vector3d>(), state[1].cast<double>(),
                                     state[2].cast<std::int64_t>()};
                      }))
      .def("__repr__", [](const Plane& p) {
        return "Plane(normal=[" + formats::PythonFloat(p.normal.x()) + ", " + formats::PythonFloat(p.normal.y()) + ", " +
               formats::PythonFloat(p.normal.z()) + "], offset=" + formats::PythonFloat(p.offset) + ", points=" +
               std::to_string(p.points) + ")";
      });
}

py::tuple CalibrationState(const Calibration& c) {
  return py::make_tuple(PosesOf(c.poses), FailedOf(c.failed), MetricsOf(c), c.points, c.point_ids, c.unit, c.model,
                        c.registration_order, c.floor_rms, c.planes, UncertaintyOf(c));
}

}  // namespace

const formats::Calibration& CalibrationFromPython(const py::object& calibration) {
  if (!py::isinstance<Calibration>(calibration)) {
    throw py::type_error("calibration: expected a Calibration, got " +
                         std::string(Py_TYPE(calibration.ptr())->tp_name));
  }
  return calibration.cast<const Calibration&>();
}

// camera_poses.json or truth.json as `calibproj compare` reads them.
void RegisterCameraPoses(py::module_& m) {
  using formats::CameraPoses;
  const auto pose_of = [](const CameraPoses& p, const std::string& name) -> const CameraPose& {
    const CameraPose* pose = p.PoseOf(name);
    if (pose == nullptr) throw py::value_error("camera " + formats::PythonRepr(name) + " has no pose");
    return *pose;
  };
  py::class_<CameraPoses>(m, "CameraPoses",
                          "World-to-camera poses by camera name (x_cam = R X + t, floor frame), the unit of their "
                          "frame, the failed cameras and those reported weak: a camera_poses.json, a truth.json, or "
                          "a calibration's poses")
      .def(py::init([](const py::dict& poses, const std::string& unit, const py::dict& failed,
                       const std::string& source, const py::iterable& weak) {
             if (unit != "arbitrary" && unit != "m") {
               throw py::value_error("unit must be one of ['arbitrary', 'm'], got " + formats::PythonRepr(unit));
             }
             CameraPoses p{PosesFrom("CameraPoses", poses), NamedTexts("CameraPoses", "failed", failed), unit, {},
                           source};
             for (const py::handle name : weak) p.weak.push_back(py::str(name).cast<std::string>());
             return p;
           }),
           py::arg("poses"), py::arg("unit") = "arbitrary", py::arg("failed") = py::dict(), py::arg("source") = "",
           py::arg("weak") = py::tuple())
      .def_property_readonly(
          "poses", [](const CameraPoses& p) { return PosesOf(p.poses); }, "{camera: (R, t)}, in the file's order")
      .def_property_readonly(
          "failed", [](const CameraPoses& p) { return FailedOf(p.failed); }, "{camera: reason}")
      .def_readonly("unit", &CameraPoses::unit, "'m' (metric) or 'arbitrary'")
      .def_readonly("source", &CameraPoses::source, "where the poses came from (a file), for messages")
      .def_property_readonly(
          "weak", [](const CameraPoses& p) { return py::frozenset(py::cast(p.weak)); },
          "cameras reported weakly determined (rotation sigma above its limit)")
      .def_property_readonly(
          "names", [](const CameraPoses& p) { return NamesOf(p.poses); }, "the cameras with a pose, in order")
      .def_property_readonly("is_metric", [](const CameraPoses& p) { return p.unit == "m"; })
      .def(
          "center", [pose_of](const CameraPoses& p, const std::string& name) { return pose_of(p, name).Centre(); },
          py::arg("name"), "the camera's centre -R^T t; ValueError for a camera without a pose")
      .def(
          "centers",
          [pose_of](const CameraPoses& p, const std::vector<std::string>& names) {
            formats::PointRows out(names.size(), 3);
            for (std::size_t i = 0; i < names.size(); ++i) out.row(i) = pose_of(p, names[i]).Centre().transpose();
            return out;
          },
          py::arg("names"), "(N, 3) the centres of these cameras");
  m.def("read_camera_poses", &formats::ReadCameraPoses, py::arg("path"),
        "The CameraPoses of a camera_poses.json or a truth.json; InputError naming the file and the problem");
}

void register_calibration(py::module_& m) {
  RegisterParts(m);
  RegisterCameraPoses(m);
  py::class_<Calibration>(
      m, "Calibration",
      "Camera poses (world-to-camera, floor frame), points and per-camera metrics of a calibration.\n\n"
      "Floor frame (docs/conventions.md): z up, floor z = 0; origin at the floor projection of the centroid of\n"
      "the registered camera centres; x along the floor projection of the first registered camera's optical\n"
      "axis. Without a metric measurement the unit is arbitrary and the first registered camera is at height 1.\n"
      "Files (save/load): camera_poses.json, metrics.json, points.ply.")
      .def(py::init(&NewCalibration), py::arg("poses"), py::arg("failed"), py::arg("metrics"), py::arg("points"),
           py::arg("point_ids"), py::arg("unit") = "arbitrary", py::arg("model") = "coplanar",
           py::arg("registration_order") = std::vector<std::string>{}, py::arg("floor_rms") = 0.0,
           py::arg("planes") = std::vector<Plane>{}, py::arg("uncertainty") = py::none(),
           "ValueError when points and ids differ in number or the unit is unknown")
      .def_static(
          "nothing_registered",
          [](const py::dict& failed, const std::string& model) {
            return formats::FromRegistration({}, {}, {}, NamedTexts("Calibration", "failed", failed), model);
          },
          py::arg("failed"), py::arg("model"), "The result when no camera could even enter the registration.")
      .def_property(
          "poses", [](const Calibration& c) { return PosesOf(c.poses); }, &SetPoses, "{camera: (R, t)} of the registered cameras, in order")
      .def_property(
          "failed", [](const Calibration& c) { return FailedOf(c.failed); }, [](Calibration& c, const py::dict& failed) { c.failed = NamedTexts("Calibration", "failed", failed); },
          "{camera: reason} of the cameras not calibrated")
      .def_property("metrics", &MetricsOf, &SetMetrics, "{camera: CameraMetrics} of every camera (copies)")
      .def_property(
          "points", [](const Calibration& c) { return ReadOnly(c.points); }, &SetPoints,
          "(P, 3) in the floor frame")
      .def_property(
          "point_ids", [](const Calibration& c) { return ReadOnly(c.point_ids); },
          [](Calibration& c, const std::vector<std::int64_t>& ids) { c.point_ids = ids; }, "(P,) one per point")
      .def_readwrite("unit", &Calibration::unit, "'arbitrary' or 'm'")
      .def_readwrite("model", &Calibration::model, "the registration model, coplanar or free")
      .def_readwrite("registration_order", &Calibration::registration_order)
      .def_readwrite("floor_rms", &Calibration::floor_rms,
                     "RMS distance of the floor's points to the floor, in the calibration's unit")
      .def_readwrite("planes", &Calibration::planes, "the planes besides the floor the projection landed on")
      .def_property("uncertainty", &UncertaintyOf, &SetUncertainty,
                    "the registered cameras' joint pose covariance (PoseUncertainty) from the final bundle "
                    "adjustment; None when not known (uncertainty.json holds it)")
      .def_property_readonly(
          "registered", [](const Calibration& c) { return NamesOf(c.poses); }, "the registered cameras, in order")
      .def("status", &Calibration::Status, py::arg("name"),
           "reference (the first registered camera: the others' sigmas are relative to it), ok, weak (its "
           "rotation known worse than the registration's limit) or failed")
      .def("summary_json", &formats::SummaryJson,
           "The per-camera summary both calibrate commands print with --json (JSON text).")
      .def(
          "pose", [](const Calibration& c, const std::string& name) { return RegisteredPose(c, name); },
          py::arg("name"), "The CameraPose of a registered camera (ValueError otherwise)")
      .def(
          "center", [](const Calibration& c, const std::string& name) { return RegisteredPose(c, name).Centre(); },
          py::arg("name"), "A registered camera's centre -R^T t (ValueError otherwise)")
      .def(
          "replace",
          [](const Calibration& c, const py::kwargs& changes) {
            py::object copy = py::cast(Calibration(c));
            for (const auto& [name, value] : changes) {
              if (!py::hasattr(copy, name)) {
                throw py::type_error("Calibration.replace: no attribute " + std::string(py::str(name)));
              }
              py::setattr(copy, name, value);
            }
            copy.cast<const Calibration&>().Check();
            return copy;
          },
          "A copy with the given attributes replaced (as dataclasses.replace)")
      .def("__copy__", [](const Calibration& c) { return Calibration(c); })
      .def("__deepcopy__", [](const Calibration& c, const py::dict&) { return Calibration(c); }, py::arg("memo"))
      .def(py::pickle(&CalibrationState,
                      [](const py::tuple& s) {
                        if (s.size() != 11) throw std::invalid_argument("Calibration: not a pickled Calibration");
                        return NewCalibration(s[0].cast<py::dict>(), s[1].cast<py::dict>(), s[2].cast<py::dict>(),
                                              s[3].cast<RowMatrix>(), s[4].cast<std::vector<std::int64_t>>(),
                                              s[5].cast<std::string>(), s[6].cast<std::string>(),
                                              s[7].cast<std::vector<std::string>>(), s[8].cast<double>(),
                                              s[9].cast<std::vector<Plane>>(),
                                              s[10].cast<std::optional<PoseUncertainty>>());
                      }))
      .def(
          "save",
          [](const Calibration& c, const std::filesystem::path& directory) {
            formats::WriteCalibration(directory, c);
          },
          py::arg("directory"),
          "Writes camera_poses.json, metrics.json and points.ply into the folder (created), each atomically")
      .def_static("load", &Load, py::arg("directory"),
                  "The calibration of a results folder (its three files); InputError naming the file and the problem")
      .def("__repr__", [](const Calibration& c) {
        return "Calibration(" + std::to_string(c.poses.size()) + " registered, " + std::to_string(c.failed.size()) +
               " failed, " + std::to_string(c.point_ids.size()) + " points, unit " + c.unit + ")";
      });
}

}  // namespace calibproj::bindings
