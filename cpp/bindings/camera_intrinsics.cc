// calibproj._core.formats.CameraIntrinsics: the one camera type (K, distortion, image
// size and the lens's mappings), which Python knows as calibproj.formats.intrinsics.Intrinsics.

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "calibproj/formats/camera_intrinsics.h"
#include "calibproj/formats/files.h"
#include "calibproj/formats/intrinsics_file.h"
#include "json_convert.h"
#include "python_objects.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

using formats::CameraIntrinsics;
using formats::Points2d;

[[noreturn]] void Refuse(const std::string& name, const std::string& problem) {
  throw py::value_error("intrinsics of " + formats::PythonRepr(name) + ": " + problem);
}

// None, or two positive integral numbers.
std::optional<std::pair<double, double>> ResolutionOf(const std::string& name, const py::object& resolution) {
  if (resolution.is_none()) return std::nullopt;
  const auto refuse = [&] {
    Refuse(name, "resolution must be two positive integers [width, height], got " +
                     py::repr(resolution).cast<std::string>());
  };
  if (!py::isinstance<py::sequence>(resolution) || py::isinstance<py::str>(resolution) || py::len(resolution) != 2) {
    refuse();
  }
  std::pair<double, double> sides;
  try {
    sides = resolution.cast<std::pair<double, double>>();
  } catch (const py::cast_error&) {
    refuse();
  }
  for (const double side : {sides.first, sides.second}) {
    if (!(std::isfinite(side) && side > 0 && side == std::floor(side))) refuse();
  }
  return sides;
}

// Numbers of any array-like, flattened.
std::vector<double> Values(const std::string& name, const char* what, const py::object& values) {
  py::array_t<double, py::array::c_style | py::array::forcecast> array;
  try {
    array = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(values);
  } catch (const py::error_already_set&) {
  }
  if (!array) Refuse(name, std::string(what) + " must be numbers, got " + py::repr(values).cast<std::string>());
  return std::vector<double>(array.data(), array.data() + array.size());
}

CameraIntrinsics Make(const std::string& name, const py::object& resolution, const py::object& K,
                      const py::object& dist) {
  const std::vector<double> K_values = Values(name, "K", K);
  if (K_values.size() != 9) Refuse(name, "K must have 9 values (3x3), got " + std::to_string(K_values.size()));
  const Eigen::Matrix3d matrix = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(K_values.data());
  try {
    return formats::MakeIntrinsics(name, ResolutionOf(name, resolution), matrix,
                                   dist.is_none() ? std::vector<double>{} : Values(name, "dist", dist));
  } catch (const std::invalid_argument& error) {
    throw py::value_error(error.what());
  }
}

// (N, 2) points of any array-like whose size is even (a single point included).
Points2d PointsOf(const py::object& points) {
  const auto array = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(points);
  if (!array) throw py::type_error("points: expected numbers, got " + py::repr(points).cast<std::string>());
  if (array.size() % 2 != 0) {
    throw py::value_error("points: expected (N, 2) coordinates, got " + std::to_string(array.size()) + " values");
  }
  return Eigen::Map<const Points2d>(array.data(), array.size() / 2, 2);
}

// A read-only copy: changing it cannot be mistaken for changing the camera.
template <typename T>
py::array ReadOnly(const T& value) {
  py::array array = py::cast(value);
  py::detail::array_proxy(array.ptr())->flags &= ~py::detail::npy_api::NPY_ARRAY_WRITEABLE_;
  return array;
}

py::object ResolutionTuple(const CameraIntrinsics& in) {
  if (!in.has_resolution) return py::none();
  return py::make_tuple(static_cast<std::int64_t>(in.width), static_cast<std::int64_t>(in.height));
}

// "[a, b, ...]" as Python prints a list of floats.
std::string PythonList(const double* values, std::size_t count) {
  std::string out = "[";
  for (std::size_t i = 0; i < count; ++i) out += (i ? ", " : "") + formats::PythonFloat(values[i]);
  return out + "]";
}

py::array_t<bool> BoolArray(const std::vector<bool>& values) {
  py::array_t<bool> out(static_cast<py::ssize_t>(values.size()));
  auto view = out.mutable_unchecked<1>();
  for (std::size_t i = 0; i < values.size(); ++i) view(i) = values[i];
  return out;
}

// A lens method applied to Python points, with the core's refusals as ValueError.
template <typename Method>
auto Mapped(Method method) {
  return [method](const CameraIntrinsics& in, const py::object& points) -> Points2d {
    return (in.*method)(PointsOf(points));
  };
}

}  // namespace

std::map<std::string, CameraIntrinsics> IntrinsicsFromPython(const py::dict& cameras) {
  std::map<std::string, CameraIntrinsics> out;
  for (const auto& [name, camera] : cameras) {
    if (!py::isinstance<CameraIntrinsics>(camera)) {
      throw py::type_error("intrinsics: expected {camera name: Intrinsics}, got " +
                           py::repr(py::type::of(camera)).cast<std::string>() + " for " +
                           py::repr(name).cast<std::string>());
    }
    out[py::str(name).cast<std::string>()] = camera.cast<const CameraIntrinsics&>();
  }
  return out;
}

void register_camera_intrinsics(py::module_& m) {
  m.attr("distortion_lengths") = py::tuple(py::cast(formats::kDistortionLengths));
  py::class_<CameraIntrinsics>(
      m, "CameraIntrinsics",
      "One camera's pinhole matrix, OpenCV distortion and image size (calibproj.formats.intrinsics.Intrinsics).\n\n"
      "name: camera name; resolution: (width, height) pixels, None when the file does not say; K: 3x3 "
      "[[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew, as OpenCV); dist: OpenCV's coefficients, 4, 5, 8, 12 or "
      "14 (None or empty: five zeros). Values are checked: ValueError naming the camera and the problem. "
      "Read-only; arrays are read-only copies; two objects are equal only when they are the same object.")
      .def(py::init(&Make), py::arg("name"), py::arg("resolution"), py::arg("K"), py::arg("dist") = py::none())
      .def_static("nominal", &formats::NominalIntrinsics, py::arg("name"), py::arg("width"), py::arg("height"),
                  py::arg("fov_deg"),
                  "A pinhole with the horizontal field of view fov_deg, square pixels, the principal point at the\n"
                  "image centre and no distortion: where a camera without any calibration starts.")
      .def_readonly("name", &CameraIntrinsics::name)
      .def_property_readonly("resolution", &ResolutionTuple, "(width, height), or None when not known")
      .def_property_readonly("K", [](const CameraIntrinsics& in) { return ReadOnly(in.K); }, "3x3 camera matrix")
      .def_property_readonly(
          "dist", [](const CameraIntrinsics& in) { return ReadOnly(in.dist); },
          "Distortion coefficients in OpenCV order")
      .def_property_readonly("has_distortion", &CameraIntrinsics::HasDistortion,
                             "Whether any distortion coefficient is not zero")
      .def(
          "image_size",
          [](const CameraIntrinsics& in) { return std::make_pair(in.ImageWidth(), in.ImageHeight()); },
          "(width, height) in pixels, or twice the principal point (+1) when the resolution is not known")
      .def("undistort_points", Mapped(&CameraIntrinsics::UndistortPixels), py::arg("pixels"),
           "Undistorted pixels (same K) of distorted pixels, (N, 2); iterates until the result, distorted again, "
           "is within 1e-9 px of the input (it converges wherever the distortion is one-to-one, see "
           "max_monotonic_radius)")
      .def("distort_points", Mapped(&CameraIntrinsics::DistortPixels), py::arg("pixels"),
           "Distorted pixels of undistorted pixels (same K), (N, 2)")
      .def("normalize", Mapped(&CameraIntrinsics::Normalize), py::arg("pixels"),
           "Pinhole normalised coordinates K^-1 [u, v, 1] of undistorted pixels, (N, 2)")
      .def("project_normalized", Mapped(&CameraIntrinsics::ProjectNormalized), py::arg("xy"),
           "Distorted pixels of normalised coordinates (X/Z, Y/Z), (N, 2)")
      .def(
          "max_monotonic_radius",
          [](const CameraIntrinsics& in, double limit, double step) {
            try {
              return in.MaxMonotonicRadius(limit, step);
            } catch (const std::invalid_argument& error) {
              throw py::value_error(error.what());
            }
          },
          py::arg("limit") = 4.0, py::arg("step") = 1e-3,
          "Normalised radius up to which the radial distortion is one-to-one (a polynomial distortion folds "
          "back beyond some radius, so points far outside the field of view can land inside the image; callers "
          "reject points beyond it); limit when it stays monotonic up to it")
      .def(
          "contains",
          [](const CameraIntrinsics& in, const py::object& pixels, double margin_px) {
            try {
              return BoolArray(in.Contains(PointsOf(pixels), margin_px));
            } catch (const std::invalid_argument& error) {
              throw py::value_error(error.what());
            }
          },
          py::arg("pixels"), py::arg("margin_px") = 0.0,
          "Which pixels lie inside the image, margin_px away from its border; ValueError when the resolution is "
          "not known")
      .def(
          "to_json", [](const CameraIntrinsics& in) { return JsonToPython(formats::IntrinsicsBody(in)); },
          "Body of our intrinsics file (camera, resolution, K, dist; resolution None when not known)")
      .def("__repr__",
           [](const CameraIntrinsics& in) {
             const Eigen::Matrix<double, 3, 3, Eigen::RowMajor> K = in.K;
             return "Intrinsics(name=" + formats::PythonRepr(in.name) + ", resolution=" +
                    py::repr(ResolutionTuple(in)).cast<std::string>() + ", K=" + PythonList(K.data(), 9) +
                    ", dist=" + PythonList(in.dist.data(), in.dist.size()) + ")";
           })
      .def("__copy__", [](const CameraIntrinsics& in) { return in; })
      .def("__deepcopy__", [](const CameraIntrinsics& in, const py::object&) { return in; }, py::arg("memo"))
      .def(py::pickle(
          [](const CameraIntrinsics& in) { return py::make_tuple(in.name, ResolutionTuple(in), in.K, in.dist); },
          [](const py::tuple& state) {
            if (state.size() != 4) throw py::value_error("CameraIntrinsics: a pickled state has 4 entries");
            return Make(state[0].cast<std::string>(), state[1], state[2], state[3]);
          }));
}

}  // namespace calibproj::bindings
