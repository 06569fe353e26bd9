// Bindings of calibproj::check: one camera of a stored calibration tested against new
// observations of its points (a bound result class, no dictionary).

#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <stdexcept>
#include <string>

#include "calibproj/check/camera_check.h"
#include "calibproj/check/option_table.h"
#include "checks.h"
#include "convert.h"
#include "ingest_options.h"
#include "knob_setter.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

py::list CheckOptionTable() {
  return KnobTable<check::CheckOptions>([](auto& o, auto&& visit) { check::VisitCheckOptions(o, visit); });
}

check::CheckOptions CheckOptionsFromKwargs(const py::kwargs& kwargs) {
  check::CheckOptions options;
  for (const auto& item : kwargs) {
    const std::string key = py::str(item.first);
    KnobSetter setter{key, item.second, "check option '" + key + "'"};
    check::VisitCheckOptions(options, setter);
    if (!setter.found) ThrowUnknownOption("check", key, CheckOptionTable());
  }
  options.Check();
  return options;
}

Eigen::Matrix3Xd Columns3(const RowMatrix& rows, const char* what) {
  return RowsOf<Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>>(rows, 3, what).transpose();
}

check::CameraCheck CheckCameraPy(const RowMatrix& K, const RowMatrix& R, const Eigen::VectorXd& t,
                                 double rotation_sigma, double centre_sigma, const RowMatrix& points,
                                 const RowMatrix& observed, const RowMatrix& volume, double width, double height,
                                 const RowMatrix& reference_points, const RowMatrix& reference_observed,
                                 const py::kwargs& kwargs) {
  const check::CheckOptions options = CheckOptionsFromKwargs(kwargs);
  if (K.rows() != 3 || K.cols() != 3) throw std::invalid_argument("K: expected shape (3, 3)");
  if (R.rows() != 3 || R.cols() != 3) throw std::invalid_argument("R: expected shape (3, 3)");
  if (t.size() != 3) throw std::invalid_argument("t: expected 3 values");
  check::CameraCheckInput input;
  input.K = {K(0, 0), K(1, 1), K(0, 2), K(1, 2), K(0, 1)};
  input.R = R;
  input.t = t;
  input.rotation_sigma = rotation_sigma;
  input.centre_sigma = centre_sigma;
  input.points = Columns3(points, "points");
  input.observed =
      RowsOf<Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>>(observed, 2, "observed").transpose();
  input.volume = Columns3(volume, "volume");
  input.reference_points = Columns3(reference_points, "reference_points");
  input.reference_observed =
      RowsOf<Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>>(reference_observed, 2, "reference_observed")
          .transpose();
  input.width = width;
  input.height = height;
  py::gil_scoped_release release;
  return check::CheckCamera(input, options);
}

}  // namespace

void register_check(py::module_& m) {
  using check::CameraCheck;
  py::class_<CameraCheck>(m, "CameraCheck", "One camera of a stored calibration tested against new observations.")
      .def_property_readonly("status", [](const CameraCheck& c) { return std::string(check::StatusName(c.status)); },
                             "unchanged, moved, rezoomed or unknown")
      .def_readonly("reason", &CameraCheck::reason, "why this status, with its figures")
      .def_readonly("points", &CameraCheck::points, "observations of calibrated points")
      .def_readonly("inliers", &CameraCheck::inliers, "observations within outlier_px of the best fit")
      .def_readonly("noise_px", &CameraCheck::noise_px, "the noise the tests assume (px)")
      .def_readonly("rms_before_px", &CameraCheck::rms_before_px, "residual RMS of the stored camera (px)")
      .def_readonly("rms_after_px", &CameraCheck::rms_after_px, "residual RMS of the camera as it is now (px)")
      .def_readonly("rotation_change_deg", &CameraCheck::rotation_change_deg)
      .def_readonly("rotation_sigma_deg", &CameraCheck::rotation_sigma_deg, "of the change (largest axis)")
      .def_readonly("centre_change", &CameraCheck::centre_change, "world units")
      .def_readonly("centre_sigma", &CameraCheck::centre_sigma, "of the change (largest axis), world units")
      .def_readonly("focal_change", &CameraCheck::focal_change, "new focal length / stored - 1")
      .def_readonly("focal_sigma", &CameraCheck::focal_sigma)
      .def_readonly("reference", &CameraCheck::reference, "what the change is measured against")
      .def_readonly("chi2", &CameraCheck::chi2, "squared Mahalanobis distance of the change")
      .def_readonly("chi2_threshold", &CameraCheck::chi2_threshold)
      .def_readonly("volume_shift_px", &CameraCheck::volume_shift_px,
                    "largest move of a working-volume point in the image (px)")
      .def_readonly("R", &CameraCheck::R, "cam_from_world rotation as the camera is now")
      .def_readonly("t", &CameraCheck::t, "cam_from_world translation as the camera is now")
      .def_readonly("focal_scale", &CameraCheck::focal_scale, "its focal length over the stored one");
  m.def("check_camera", &CheckCameraPy, py::arg("K"), py::arg("R"), py::arg("t"), py::arg("rotation_sigma"),
        py::arg("centre_sigma"), py::arg("points"), py::arg("observed"), py::arg("volume"), py::arg("width"),
        py::arg("height"), py::arg("reference_points") = RowMatrix(0, 3),
        py::arg("reference_observed") = RowMatrix(0, 2),
        "Tests one stored camera (K, R, t; pose sigmas in rad and world units) against its new undistorted\n"
        "observations (N, 2) of stored points (N, 3), the working volume (M, 3) and image size giving the\n"
        "practical test; the camera's observations (M, 2) of stored points (M, 3) that the calibration was made\n"
        "from are the reference of the change (without them, the stored sigmas); keyword options as\n"
        "option_table() lists them.");
  m.def(
      "check_options", [](const py::kwargs& kwargs) { CheckOptionsFromKwargs(kwargs); },
      "Raises ValueError naming the first check option (keyword) that is unknown or out of range.");
  m.def("option_table", &CheckOptionTable,
        "Every check knob as {name, default, help}, in order: the one declaration calibproj.check.CheckOptions "
        "and both command lines are made from.");
}

}  // namespace calibproj::bindings
