// Bindings of calibproj::selfcal: numpy arrays in, its Result out.

#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cmath>
#include <filesystem>
#include <iterator>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "calibproj/formats/files.h"
#include "calibproj/formats/tracks.h"
#include "calibproj/selfcal/lens_problem.h"
#include "calibproj/selfcal/option_table.h"
#include "calibproj/selfcal/planar_autocalibration.h"
#include "calibproj/selfcal/planar_cost.h"
#include "calibproj/selfcal/refinement.h"
#include "calibproj/selfcal/rounds.h"
#include "calibproj/selfcal/self_calibration.h"
#include "checks.h"
#include "convert.h"
#include "knob_setter.h"
#include "python_objects.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

std::vector<selfcal::LensShape> Shapes(const RowMatrix& shapes) {
  const auto rows = RowsOf<Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>>(shapes, 2, "shapes");
  std::vector<selfcal::LensShape> out(rows.rows());
  for (int c = 0; c < rows.rows(); ++c) out[c] = {rows(c, 0), rows(c, 1)};
  return out;
}

selfcal::Result SelfCalibratePy(const Eigen::VectorXi& camera_index, const Eigen::VectorXi& point_index,
                         const RowMatrix& observed, const RowMatrix& lenses, const RowMatrix& shapes,
                         const std::vector<std::vector<int>>& refine, const RowMatrix& poses, const RowMatrix& points,
                         const std::string& loss, double loss_scale, int max_iterations, int num_threads,
                         bool compute_covariance) {
  selfcal::Options options;
  options.loss = ParseLoss(loss);
  options.loss_scale_px = loss_scale;
  options.max_iterations = max_iterations;
  options.num_threads = num_threads;
  options.compute_covariance = compute_covariance;
  selfcal::Data data;
  data.camera_index = camera_index;
  data.point_index = point_index;
  data.observed = RowsOf<ba::PixelMatrix>(observed, 2, "observed");
  data.lenses = RowsOf<selfcal::LensMatrix>(lenses, selfcal::kLensSize, "lenses");
  data.shapes = Shapes(shapes);
  data.refine = refine;
  data.poses = RowsOf<ba::PoseMatrix>(poses, 6, "poses");
  data.points = RowsOf<selfcal::FloorMatrix>(points, 2, "points");
  selfcal::Result result;
  {
    py::gil_scoped_release release;
    result = selfcal::SelfCalibrate(data, options);
  }
  return result;
}

void RegisterResult(py::module_& m) {
  using selfcal::Result;
  py::class_<Result>(m, "Result", "A self-calibration's solution: lenses, poses and floor points, and how well they fit.")
      .def_readonly("initial_cost", &Result::initial_cost)
      .def_readonly("final_cost", &Result::final_cost)
      .def_readonly("iterations", &Result::iterations)
      .def_readonly("termination", &Result::termination, "Ceres's termination message")
      .def_readonly("usable", &Result::usable, "the solver's solution can be used")
      .def_readonly("gauge_points", &Result::gauge_points, "the two points held fixed (the floor's gauge)")
      .def_readonly("lenses", &Result::lenses, "(C, 8) [f, cx, cy, k1, k2, p1, p2, k3]")
      .def_readonly("poses", &Result::poses, "(C, 6) cam_from_floor [angle-axis, t]")
      .def_readonly("points", &Result::points, "(P, 2) on the floor z = 0")
      .def_readonly("residuals", &Result::residuals, "(N, 2) px, NaN where not projectable")
      .def_readonly("noise_px", &Result::noise_px, "(C,) RMS of one residual coordinate per camera")
      .def_readonly("lens_covariance", &Result::lens_covariance,
                    "(8C, 8C) the lenses' joint covariance, camera c in rows and columns 8c to 8c + 7, zero\n"
                    "outside the refined entries, in each camera's measured noise; (0, 0) when not computed")
      .def("lens_covariance_of", &Result::LensCovarianceOf, py::arg("a"), py::arg("b"),
           "(8, 8) the covariance of camera a's lens with camera b's (ValueError out of range)");
}

std::vector<Knob> SelfCalibrationOptionTable() {
  return KnobTable<selfcal::SelfCalibrationOptions>(
      [](auto& o, auto&& visit) { selfcal::VisitSelfCalibrationOptions(o, visit); });
}

selfcal::SelfCalibrationOptions SelfCalibrationOptionsFrom(const py::dict& values) {
  return OptionsFromKeywords<selfcal::SelfCalibrationOptions>(
      values, "self-calibration", [](auto& o, auto&& visit) { selfcal::VisitSelfCalibrationOptions(o, visit); });
}

// The core's log lines to a Python callable (calibproj.selfcal.lenses's logger.info).
std::function<void(const std::string&)> LogTo(const py::function& log) {
  // Copies of the std::function made without the GIL share the one reference.
  auto function = std::make_shared<py::function>(log);
  return [function](const std::string& line) {
    py::gil_scoped_acquire acquire;
    (*function)(line);
  };
}

void RegisterRefinement(py::module_& m) {
  using selfcal::LensReport;
  using selfcal::RefineRequest;
  py::class_<RefineRequest>(m, "RefineRequest", "Which lens entries to refine, per camera ('*': every camera not named).")
      .def_static("parse", &RefineRequest::Parse, py::arg("items"),
                  "From 'focal,k1,k2' (every camera) and/or 'CAMERA=focal,k1' items; 'CAMERA=none' holds that\n"
                  "camera. ValueError naming the bad item.")
      .def("of", &RefineRequest::Of, py::arg("camera"), "the entries asked for this camera")
      .def("cameras_named", &RefineRequest::CamerasNamed)
      .def("check_cameras", &RefineRequest::CheckCameras, py::arg("camera_names"),
           "ValueError when the request names a camera that is not among camera_names");
  py::class_<LensReport>(m, "LensReport", "What the self-calibration did to one camera.")
      .def_readonly("camera", &LensReport::camera)
      .def_readonly("requested", &LensReport::requested)
      .def_readonly("refined", &LensReport::refined, "entries changed from the given values")
      .def_property_readonly(
          "held",
          [](const LensReport& r) {
            py::dict out;
            for (const auto& [entry, why] : r.held) out[py::str(entry)] = why;
            return out;
          },
          "entry -> why its given value was kept")
      .def_readonly("focal_sigma", &LensReport::focal_sigma, "px")
      .def_readonly("principal_point_sigma_px", &LensReport::principal_point_sigma_px)
      .def_readonly("distortion_sigma_px", &LensReport::distortion_sigma_px, "worst over the image")
      .def_readonly("noise_px", &LensReport::noise_px, "RMS of one residual coordinate")
      .def_readonly("coverage", &LensReport::coverage,
                    "how far towards the image corners the observations reach (0-1)")
      .def_readonly("left_out", &LensReport::left_out,
                    "its focal length not determined, its observations left out of the solve")
      .def_readonly("observations", &LensReport::observations)
      .def_readonly("systematic_px", &LensReport::systematic_px,
                    "RMS of the smooth pattern (a quadratic field over the image) left in its residuals")
      .def_readonly("systematic_chi2", &LensReport::systematic_chi2,
                    "the chi-square that pattern explains, in units of the camera's noise")
      .def_readonly("misfit", &LensReport::misfit, "why that pattern makes its intrinsics untrustworthy, or None")
      .def_property_readonly("weak_reason", &selfcal::WeakReason,
                             "why its pose is weak after the self-calibration (focal length held, or a misfit), "
                             "or None")
      .def_readonly("given", &LensReport::given,
                    "the lens entries given, in the order of lens_entries (None before a solve)")
      .def_readonly("result", &LensReport::result, "the lens entries found, in that order (None before a solve)");
  using selfcal::JointLensCovariance;
  py::class_<JointLensCovariance>(m, "LensCovariance",
                                  "How the refined lenses err together: their joint covariance over\n"
                                  "[f, cx, cy, k1, k2, p1, p2, k3], in pixels of each camera's measured noise.")
      .def(py::init<>())
      .def_property_readonly("cameras", [](const JointLensCovariance& c) { return py::tuple(py::cast(c.cameras)); })
      .def_readonly("matrix", &JointLensCovariance::matrix, "(8n, 8n), the k-th camera in rows and columns 8k..8k+7")
      .def("among", &JointLensCovariance::Among, py::arg("names"),
           "(8n, 8n) the joint covariance of these cameras' lenses, in their order")
      .def(
          "of", [](const JointLensCovariance& c, const std::string& name) { return c.Among({name}); },
          py::arg("name"), "(8, 8) the covariance of this camera's lens");
  using selfcal::SelfCalibration;
  py::class_<SelfCalibration>(m, "SelfCalibration",
                              "Refined intrinsics (every camera of the input), a report per camera asked for, and\n"
                              "the joint covariance of the lenses refined.")
      .def_readonly("intrinsics", &SelfCalibration::intrinsics, "camera -> formats.CameraIntrinsics")
      .def_property_readonly(
          "reports",
          [](const SelfCalibration& s) {
            py::dict out;
            for (const auto& report : s.reports) out[py::str(report.camera)] = py::cast(report);
            return out;
          },
          "camera -> LensReport, in the order of the tracks")
      .def_readonly("lens_covariance", &SelfCalibration::lens_covariance);
}

selfcal::SelfCalibration SelfCalibrateFromPython(const formats::Tracks& tracks, const py::dict& intrinsics,
                                                 const py::object& calibration, const selfcal::RefineRequest& request,
                                                 const py::dict& options, int num_threads,
                                                 const std::optional<py::dict>& given,
                                                 const std::optional<selfcal::SelfCalibration>& earlier,
                                                 const py::function& log_line) {
  const auto core_intrinsics = IntrinsicsFromPython(intrinsics);
  const formats::Calibration core_calibration = CalibrationFromPython(calibration);
  const auto settings = SelfCalibrationOptionsFrom(options);
  std::optional<selfcal::IntrinsicsMap> core_given;
  if (given) core_given = IntrinsicsFromPython(*given);
  const auto log = LogTo(log_line);  // made (and destroyed) with the GIL held
  py::gil_scoped_release release;
  return selfcal::SelfCalibrate(tracks, core_intrinsics, core_calibration, request, settings, num_threads,
                                core_given ? &*core_given : nullptr, earlier ? &earlier->reports : nullptr, log);
}

// The rounds of a calibration's self-calibration (selfcal/rounds.h), each registration
// made by register_tracks(tracks, intrinsics, lens_covariance or None), a Python callable
// that returns a Calibration (the Python driver's).
selfcal::RefinedCalibration RefineWithRegistrationsFromPython(
    const py::object& calibration, const formats::Tracks& tracks, const py::dict& intrinsics,
    const selfcal::RefineRequest& request, const py::dict& options, int num_threads,
    const py::function& register_tracks, const py::function& log_line) {
  const formats::Calibration first = CalibrationFromPython(calibration);
  const auto core_intrinsics = IntrinsicsFromPython(intrinsics);
  const auto settings = SelfCalibrationOptionsFrom(options);
  const auto log = LogTo(log_line);  // made (and destroyed) with the GIL held
  auto function = std::make_shared<py::function>(register_tracks);
  const selfcal::RegisterFunction registered = [function](const formats::Tracks& all,
                                                          const selfcal::IntrinsicsMap& lenses,
                                                          const selfcal::JointLensCovariance* covariance) {
    py::gil_scoped_acquire acquire;
    const py::object result = (*function)(all, lenses, covariance != nullptr ? py::cast(*covariance) : py::none());
    return CalibrationFromPython(result);
  };
  py::gil_scoped_release release;
  return selfcal::RefineWithRegistrations(first, tracks, core_intrinsics, request, settings, num_threads, registered,
                                          log);
}

void RegisterRefinedCalibration(py::module_& m) {
  using selfcal::RefinedCalibration;
  py::class_<RefinedCalibration>(m, "RefinedCalibration",
                                 "A calibration registered again with the lenses its self-calibration refined.")
      // Copies, as every Calibration and Tracks attribute reads.
      .def_property_readonly(
          "calibration", [](const RefinedCalibration& r) { return r.calibration; }, "registered with the refined lenses")
      .def_property_readonly(
          "tracks", [](const RefinedCalibration& r) { return r.tracks; }, "the input's tracks, re-expressed with them")
      .def_readonly("intrinsics", &RefinedCalibration::intrinsics,
                    "camera -> formats.CameraIntrinsics, every camera of the input")
      .def_property_readonly(
          "result", [](const RefinedCalibration& r) { return r.result; }, "the last round's SelfCalibration")
      .def_readonly("weak", &RefinedCalibration::weak, "[(camera, reason)] of the cameras marked weak");
}

}  // namespace

void register_selfcal(py::module_& m) {
  m.attr("lens_size") = selfcal::kLensSize;
  m.attr("lens_entries") = py::tuple(py::cast(std::vector<std::string>(std::begin(selfcal::kLensEntries),
                                                                       std::end(selfcal::kLensEntries))));
  RegisterResult(m);
  RegisterRefinement(m);
  m.attr("refine_intrinsics_help") = selfcal::kRefineIntrinsicsHelp;
  m.def("option_table", &SelfCalibrationOptionTable,
        "Every self-calibration knob as a Knob (name, default, help), in order; SelfCalibrationOptions is made from it.");
  m.def(
      "check_options", [](const py::kwargs& kwargs) { SelfCalibrationOptionsFrom(kwargs); },
      "ValueError naming the first knob that is not a positive number, or an unknown one.");
  m.def("refine_lenses", &SelfCalibrateFromPython, py::arg("tracks"), py::arg("intrinsics"), py::arg("calibration"),
        py::arg("request"), py::kw_only(), py::arg("options"), py::arg("num_threads") = 1,
        py::arg("given") = py::none(), py::arg("earlier") = py::none(), py::arg("log"),
        R"doc(The requested lens entries of the registered cameras of calibration, refined (a SelfCalibration).

tracks are undistorted with intrinsics ({name: Intrinsics}), where the refinement starts; an entry
held keeps its value in given (default: intrinsics). A later round passes the first round's result
as intrinsics, the user's values as given and the first round's SelfCalibration as earlier: the
entries it chose are refined again without choosing anew. options: {knob: value}
(option_table()). Each camera's line goes to log(line). Releases the GIL.)doc");
  RegisterRefinedCalibration(m);
  m.def("refine_with_registrations", &RefineWithRegistrationsFromPython, py::arg("calibration"), py::arg("tracks"),
        py::arg("intrinsics"), py::arg("request"), py::kw_only(), py::arg("options"), py::arg("num_threads") = 1,
        py::arg("register"), py::arg("log"),
        R"doc(Self-calibration as a calibration runs it (a RefinedCalibration): from the closed-form start,
options["rounds"] rounds of lens refinement, each followed by register(tracks, intrinsics,
lens_covariance) (a Calibration; lens_covariance None before any refinement); then every camera
whose lens it cannot vouch for is marked weak.

calibration: registered from tracks (undistorted with intrinsics, {name: Intrinsics}), with at
least one camera registered. Each camera's line goes to log(line). Releases the GIL but for the
calls of register and log.)doc");
  m.def(
      "mark_untrusted_lenses_weak",
      [](const selfcal::SelfCalibration& result, formats::Calibration& calibration) {
        return selfcal::MarkUntrustedLensesWeak(result, calibration);
      },
      py::arg("result"), py::arg("calibration"),
      "Marks weak, in place, every registered camera of the calibration whose lens the self-calibration cannot "
      "vouch for (its focal length held, or a misfit); [(camera, reason)] of those it marked.");
  m.def(
      "closed_form_start",
      [](const formats::Tracks& tracks, const py::dict& intrinsics, const py::object& calibration,
         const selfcal::RefineRequest& request, const py::dict& options, const py::function& log) {
        return selfcal::ClosedFormStart(tracks, IntrinsicsFromPython(intrinsics),
                                        CalibrationFromPython(calibration), request,
                                        SelfCalibrationOptionsFrom(options), LogTo(log));
      },
      py::arg("tracks"), py::arg("intrinsics"), py::arg("calibration"), py::arg("request"), py::kw_only(),
      py::arg("options"), py::arg("log"),
      "{name: formats.CameraIntrinsics} to start the refinement from: the given ones, but for a camera whose\n"
      "focal length is to be refined and disagrees by more than closed_form_min_change with the closed-form\n"
      "planar autocalibration, that one.");
  m.def(
      "refused_cameras",
      [](const selfcal::RefineRequest& request, const py::dict& intrinsics, const std::vector<std::string>& names) {
        return selfcal::RefusedCameras(request, IntrinsicsFromPython(intrinsics), names);
      },
      py::arg("request"), py::arg("intrinsics"), py::arg("camera_names"),
      "[(camera, reason)] of the cameras whose lens cannot be refined (ValueError for a camera the request\n"
      "names that is not among camera_names).");
  m.def(
      "convert_tracks",
      [](const formats::Tracks& tracks, const py::dict& given, const py::dict& refined) {
        return selfcal::ConvertTracks(tracks, IntrinsicsFromPython(given), IntrinsicsFromPython(refined));
      },
      py::arg("tracks"), py::arg("given"), py::arg("refined"),
      "Tracks (formats.Tracks) undistorted with given re-expressed as undistorted with refined.");
  m.def(
      "write_self_calibration",
      [](const std::filesystem::path& path, const selfcal::SelfCalibration& result, const py::dict& given,
         const py::dict& options) {
        formats::AtomicWrite(path, selfcal::SelfCalibrationJson(result, IntrinsicsFromPython(given),
                                                                SelfCalibrationOptionsFrom(options)));
      },
      py::arg("path"), py::arg("result"), py::arg("given"), py::arg("options"),
      "self_calibration.json: per camera what was refined or held and why, the uncertainties, and the\n"
      "intrinsics given; written atomically.");
  m.def(
      "focal_lengths",
      [](const std::vector<std::pair<std::string, Eigen::Matrix3d>>& homographies,
         const std::map<std::string, double>& known) {
        const selfcal::PlanarAutocalibration found = selfcal::FocalLengths(homographies, known);
        return py::make_tuple(found.focal, found.residual, found.circular_point);
      },
      py::arg("homographies"), py::arg("known"),
      "(focal, residual, circular_point): planar autocalibration of the cameras' floor homographies\n"
      "([(name, H)], floor -> pixels centred on the principal point) with the focal lengths of `known`\n"
      "given. ValueError when they cannot determine the others.");
  m.def("self_calibrate", &SelfCalibratePy, py::arg("camera_index"), py::arg("point_index"), py::arg("observed"),
        py::arg("lenses"), py::arg("shapes"), py::arg("refine"), py::arg("poses"), py::arg("points"), py::kw_only(),
        py::arg("loss") = "none", py::arg("loss_scale") = 1.0, py::arg("max_iterations") = 100,
        py::arg("num_threads") = 1, py::arg("compute_covariance") = true,
        R"doc(Poses, floor points and lenses refined together (Ceres), from raw pixels.

Observations: camera_index (N,), point_index (N,), observed (N, 2) raw pixels.
lenses (C, 8) [f, cx, cy, k1, k2, p1, p2, k3]; shapes (C, 2) [fy/fx, skew/fx];
refine: per camera the lens entries (indices into the 8) that move; poses (C, 6)
cam_from_floor [angle-axis, t]; points (P, 2) on the floor z = 0. Two points fix the
floor's gauge. Returns a Result (the refined lenses, poses, points, residuals, per-camera
noise and, if compute_covariance, the lenses' joint covariance in each camera's measured
noise). Bad input raises ValueError naming the problem. Releases the GIL.)doc");
  m.def(
      "residual_by_lens",
      [](const Eigen::Matrix3d& K, const std::vector<double>& distortion, const Eigen::Vector2d& normalised) {
        if (!K.allFinite() || !(K(0, 0) > 0.0) || !(K(1, 1) > 0.0)) throw std::invalid_argument("K: positive focal lengths needed");
        for (double value : distortion) {
          if (!std::isfinite(value)) throw std::invalid_argument("distortion: non-finite value");
        }
        if (!normalised.allFinite()) throw std::invalid_argument("normalised: non-finite value");
        double lens[selfcal::kLensSize];
        selfcal::LensShape shape;
        selfcal::LensOf(K, distortion.data(), static_cast<int>(distortion.size()), lens, &shape);
        return Eigen::Matrix<double, 2, selfcal::kLensSize>(selfcal::ResidualByLens(lens, shape, normalised));
      },
      py::arg("K"), py::arg("distortion"), py::arg("normalised"),
      "d residual / d lens (2, 8) [f, cx, cy, k1, k2, p1, p2, k3] of a centre whose undistorted normalised\n"
      "coordinates are `normalised`, for intrinsics K and OpenCV distortion: how a lens error moves its\n"
      "undistorted pixel residual (projected minus observed).");
  m.def(
      "evaluate_planar_lens_cost",
      [](const Eigen::VectorXd& shape, const Eigen::VectorXd& observed, const Eigen::VectorXd& pose,
         const Eigen::VectorXd& point, const Eigen::VectorXd& lens) {
        if (shape.size() != 2 || observed.size() != 2 || pose.size() != 6 || point.size() != 2 ||
            lens.size() != selfcal::kLensSize) {
          throw std::invalid_argument("expected shape (2,), observed (2,), pose (6,), point (2,), lens (8,)");
        }
        const selfcal::PlanarLensCost cost({shape(0), shape(1)}, observed);
        const double* blocks[3] = {pose.data(), point.data(), lens.data()};
        Eigen::Matrix<double, 2, 6, Eigen::RowMajor> J_pose;
        Eigen::Matrix<double, 2, 2, Eigen::RowMajor> J_point;
        selfcal::LensJacobian J_lens;
        double* jacobians[3] = {J_pose.data(), J_point.data(), J_lens.data()};
        Eigen::Vector2d residual;
        const bool ok = cost.Evaluate(blocks, residual.data(), jacobians);
        return py::make_tuple(ok, residual, RowMatrix(J_pose), RowMatrix(J_point), RowMatrix(J_lens));
      },
      py::arg("shape"), py::arg("observed"), py::arg("pose"), py::arg("point"), py::arg("lens"),
      "Diagnostics: (ok, residual, J_pose, J_point, J_lens) of the floor-point lens cost.");
}

}  // namespace calibproj::bindings
