// Bindings of calibproj::check: one camera of a stored calibration tested against new
// observations of its points (a bound result class, no dictionary).

#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <stdexcept>
#include <string>

#include <pybind11/stl/filesystem.h>

#include "calibproj/check/calibration_check.h"
#include "calibproj/check/camera_check.h"
#include "calibproj/check/option_table.h"
#include "calibproj/formats/files.h"
#include "calibproj/formats/tracks.h"
#include "checks.h"
#include "convert.h"
#include "knob_setter.h"
#include "python_objects.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

std::vector<Knob> CheckOptionTable() {
  return KnobTable<check::CheckOptions>([](auto& o, auto&& visit) { check::VisitCheckOptions(o, visit); });
}

check::CheckOptions CheckOptionsFromKwargs(const py::kwargs& kwargs) {
  return OptionsFromKeywords<check::CheckOptions>(kwargs, "check",
                                                  [](auto& o, auto&& visit) { check::VisitCheckOptions(o, visit); });
}

Eigen::Matrix3Xd Columns3(const RowMatrix& rows, const char* what) {
  return RowsOf<Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>>(rows, 3, what).transpose();
}

// A check input holding the stored camera (K, R, t), their shapes checked.
check::CameraCheckInput StoredCamera(const RowMatrix& K, const RowMatrix& R, const Eigen::VectorXd& t) {
  if (K.rows() != 3 || K.cols() != 3) throw std::invalid_argument("K: expected shape (3, 3)");
  if (R.rows() != 3 || R.cols() != 3) throw std::invalid_argument("R: expected shape (3, 3)");
  if (t.size() != 3) throw std::invalid_argument("t: expected 3 values");
  check::CameraCheckInput input;
  input.K = {K(0, 0), K(1, 1), K(0, 2), K(1, 2), K(0, 1)};
  input.R = R;
  input.t = t;
  return input;
}

check::CameraCheck CheckCameraPy(const RowMatrix& K, const RowMatrix& R, const Eigen::VectorXd& t,
                                 double rotation_sigma, double centre_sigma, const RowMatrix& points,
                                 const RowMatrix& observed, const RowMatrix& volume, double width, double height,
                                 const RowMatrix& reference_points, const RowMatrix& reference_observed,
                                 const std::vector<double>& dist, const py::kwargs& kwargs) {
  const check::CheckOptions options = CheckOptionsFromKwargs(kwargs);
  check::CameraCheckInput input = StoredCamera(K, R, t);
  input.dist = dist;
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

double PredictedShiftSigmaPy(const RowMatrix& K, const RowMatrix& R, const Eigen::VectorXd& t, const RowMatrix& points,
                             const RowMatrix& volume, double width, double height, double noise_px) {
  check::CameraCheckInput input = StoredCamera(K, R, t);
  input.points = Columns3(points, "points");
  input.observed = Eigen::Matrix2Xd::Zero(2, input.points.cols());
  input.volume = Columns3(volume, "volume");
  input.width = width;
  input.height = height;
  py::gil_scoped_release release;
  return check::PredictedShiftSigma(input, noise_px);
}

check::CalibrationCheck CheckCalibrationPy(const py::object& calibration, const py::dict& intrinsics,
                                            const formats::Tracks& tracks, const formats::Tracks* stored_tracks,
                                            const std::map<std::string, std::string>& unusable,
                                            const std::map<std::string, std::string>& not_seen,
                                            const py::kwargs& kwargs) {
  const check::CheckOptions options = CheckOptionsFromKwargs(kwargs);
  const formats::Calibration stored = CalibrationFromPython(calibration);
  const auto cameras = IntrinsicsFromPython(intrinsics);
  check::CheckInputs inputs{&stored, &cameras, unusable, &tracks, stored_tracks, not_seen};
  py::gil_scoped_release release;
  return check::CheckCalibration(inputs, options);
}

// The calibration as the cameras are now: (Calibration, {camera: CameraIntrinsics},
// Tracks), the core's bound types.
py::tuple RepairedPy(const py::object& calibration, const py::dict& intrinsics, const formats::Tracks& tracks,
                     const formats::Tracks& stored_tracks, const check::CalibrationCheck& result,
                     double weak_rotation_sigma_deg) {
  const formats::Calibration stored = CalibrationFromPython(calibration);
  const auto cameras = IntrinsicsFromPython(intrinsics);
  const check::CheckInputs inputs{&stored, &cameras, {}, &tracks, &stored_tracks, {}};
  const check::Repair repair = check::Repaired(inputs, result, weak_rotation_sigma_deg);
  return py::make_tuple(repair.calibration, repair.intrinsics, repair.tracks);
}

// A figure of a tested camera's check; None for the others.
template <typename T>
auto Figure(T check::CameraCheck::*field) {
  return [field](const check::CameraVerdict& v) -> std::optional<T> {
    return v.figures ? std::optional<T>((*v.figures).*field) : std::nullopt;
  };
}

void RegisterVerdicts(py::module_& m) {
  using check::CameraVerdict;
  py::class_<CameraVerdict>(m, "CameraVerdict",
                            "One camera's check: its status, why, and the figures behind it (pixels are undistorted "
                            "pixels; centre in the calibration's unit). Figures are None for a camera not tested.")
      .def_readonly("status", &CameraVerdict::status, "unchanged, moved, rezoomed, not seen or unknown")
      .def_readonly("reason", &CameraVerdict::reason, "why this status, with its figures")
      .def_readonly("points", &CameraVerdict::points, "observations of calibrated points")
      .def_readonly("inliers", &CameraVerdict::inliers, "observations within outlier_px of the best fit")
      .def_property_readonly("noise_px", Figure(&check::CameraCheck::noise_px))
      .def_property_readonly("rms_before_px", Figure(&check::CameraCheck::rms_before_px))
      .def_property_readonly("rms_after_px", Figure(&check::CameraCheck::rms_after_px))
      .def_property_readonly("rotation_change_deg", Figure(&check::CameraCheck::rotation_change_deg))
      .def_property_readonly("rotation_sigma_deg", Figure(&check::CameraCheck::rotation_sigma_deg))
      .def_property_readonly("centre_change", Figure(&check::CameraCheck::centre_change))
      .def_property_readonly("centre_sigma", Figure(&check::CameraCheck::centre_sigma))
      .def_property_readonly("focal_change", Figure(&check::CameraCheck::focal_change))
      .def_property_readonly("focal_sigma", Figure(&check::CameraCheck::focal_sigma))
      .def_property_readonly("volume_shift_px", Figure(&check::CameraCheck::volume_shift_px))
      .def_property_readonly("volume_shift_sigma_px", Figure(&check::CameraCheck::volume_shift_sigma_px))
      .def_property_readonly("R", Figure(&check::CameraCheck::R), "cam_from_world rotation as the camera is now")
      .def_property_readonly("t", Figure(&check::CameraCheck::t), "cam_from_world translation as the camera is now")
      .def_property_readonly(
          "focal_scale", [](const CameraVerdict& v) { return v.figures ? v.figures->focal_scale : 1.0; },
          "its focal length over the stored one");
  using check::CalibrationCheck;
  py::class_<CalibrationCheck>(m, "CalibrationCheck",
                               "Every camera's verdict, and whether the stored calibration can be trusted as the "
                               "reference of a repair.")
      .def_property_readonly(
          "cameras",
          [](const CalibrationCheck& c) {
            py::dict cameras;
            for (const auto& [name, verdict] : c.cameras) cameras[py::str(name)] = py::cast(verdict);
            return cameras;
          },
          "{camera: CameraVerdict}, the registered cameras then the failed ones")
      .def_readonly("trusted", &CalibrationCheck::trusted,
                    "the unchanged cameras are a clear majority of those tested")
      .def_readonly("message", &CalibrationCheck::message)
      .def_readonly("unit", &CalibrationCheck::unit)
      .def_property_readonly("tested", &CalibrationCheck::Tested, "the cameras unchanged, moved or re-zoomed")
      .def_property_readonly("changed", &CalibrationCheck::Changed, "the cameras moved or re-zoomed")
      .def("json", &check::CheckJson, "check.json's text")
      .def("table", &check::CheckTable, "one line per camera under a header, as both commands print it")
      .def("exit_status", &check::CheckExitStatus, py::arg("repaired"),
           "the commands' exit status: 0 confirmed or repaired, 3 not confirmed, 4 untrusted");
}

}  // namespace

void register_check(py::module_& m) {
  RegisterVerdicts(m);
  m.def("check_calibration", &CheckCalibrationPy, py::arg("calibration"), py::arg("intrinsics"), py::arg("tracks"),
        py::arg("stored_tracks") = py::none(), py::arg("unusable") = std::map<std::string, std::string>{},
        py::arg("not_seen") = std::map<std::string, std::string>{},
        "Tests every camera of a Calibration ({camera: Intrinsics}) on a check projection's Tracks; the\n"
        "calibration's own Tracks give each camera's reference. unusable: why some cameras have no intrinsics;\n"
        "not_seen: why some gave no observation. Keyword options as option_table() lists them. ValueError when\n"
        "there is nothing to check against.");
  m.def("repaired", &RepairedPy, py::arg("calibration"), py::arg("intrinsics"), py::arg("tracks"),
        py::arg("stored_tracks"), py::arg("check"), py::arg("weak_rotation_sigma_deg"),
        "The calibration as the cameras are now: the changed cameras' poses, focal lengths, metrics and\n"
        "observations (those of tracks) replace the stored ones. Returns (_core.formats.Calibration,\n"
        "{camera: _core.formats.CameraIntrinsics}, _core.formats.Tracks); ValueError with the check's message\n"
        "when it is not trusted.");
  m.def(
      "write_check",
      [](const std::filesystem::path& path, const check::CalibrationCheck& check) {
        formats::AtomicWrite(path, check::CheckJson(check));
      },
      py::arg("path"), py::arg("check"), "Writes check.json atomically.");
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
      .def_readonly("volume_shift_sigma_px", &CameraCheck::volume_shift_sigma_px, "its uncertainty (1 sigma, px)")
      .def_readonly("R", &CameraCheck::R, "cam_from_world rotation as the camera is now")
      .def_readonly("t", &CameraCheck::t, "cam_from_world translation as the camera is now")
      .def_readonly("focal_scale", &CameraCheck::focal_scale, "its focal length over the stored one");
  m.def("check_camera", &CheckCameraPy, py::arg("K"), py::arg("R"), py::arg("t"), py::arg("rotation_sigma"),
        py::arg("centre_sigma"), py::arg("points"), py::arg("observed"), py::arg("volume"), py::arg("width"),
        py::arg("height"), py::arg("reference_points") = RowMatrix(0, 3),
        py::arg("reference_observed") = RowMatrix(0, 2), py::arg("dist") = std::vector<double>{},
        "Tests one stored camera (K, R, t; pose sigmas in rad and world units) against its new undistorted\n"
        "observations (N, 2) of stored points (N, 3), the working volume (M, 3) and image size giving the\n"
        "practical test; the camera's observations (M, 2) of stored points (M, 3) that the calibration was made\n"
        "from are the reference of the change (without them, the stored sigmas); dist: the stored OpenCV\n"
        "distortion (the observations are undistorted pixels of K; empty: none); keyword options as\n"
        "option_table() lists them.");
  m.def("predicted_shift_sigma", &PredictedShiftSigmaPy, py::arg("K"), py::arg("R"), py::arg("t"),
        py::arg("points"), py::arg("volume"), py::arg("width"), py::arg("height"), py::arg("noise_px"),
        "What a check of the camera (K, R, t) on these stored points (N, 3) could resolve: the uncertainty\n"
        "(1 sigma, px) of how far the working volume (M, 3) seems to move in its image (width x height) when\n"
        "its pose is fitted to them with noise_px of detection noise; inf when they fix no pose.");
  m.def(
      "working_volume",
      [](const py::object& calibration) -> Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> {
        return check::WorkingVolume(CalibrationFromPython(calibration)).transpose();
      },
      py::arg("calibration"), "The check's working volume (M, 3) of a calibration: its practical test's points.");
  m.def(
      "check_options", [](const py::kwargs& kwargs) { CheckOptionsFromKwargs(kwargs); },
      "Raises ValueError naming the first check option (keyword) that is unknown or out of range.");
  m.def("option_table", &CheckOptionTable,
        "Every check knob as a Knob (name, default, help), in order: the one declaration calibproj.check.repair.CheckOptions "
        "and both command lines are made from.");
}

}  // namespace calibproj::bindings
