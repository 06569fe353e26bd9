// Bindings of calibproj::registration: the Reconstruction and its steps.

#include <pybind11/eigen.h>
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <string>
#include <type_traits>

#include "calibproj/formats/calibration.h"
#include "calibproj/registration/incremental.h"
#include "calibproj/registration/option_table.h"
#include "calibproj/registration/reconstruction.h"
#include "calibproj/registration/result.h"
#include "calibproj/registration/view_score.h"
#include "checks.h"
#include "convert.h"
#include "knob_setter.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

using registration::Reconstruction;

registration::Options OptionsFromKwargs(const py::kwargs& kwargs) {
  registration::Options o;
  for (const auto& item : kwargs) {
    const std::string key = py::str(item.first);
    KnobSetter setter{key, item.second, "registration option '" + key + "'"};
    registration::VisitRegistrationOptions(o, setter);
    if (!setter.found) throw std::invalid_argument("registration: unknown option '" + key + "'");
  }
  o.Check();
  return o;
}

// Per knob: name, default (an enumerated one by name), help and, for an enumerated
// one, its choices; the Python options class and flags are made from it.
std::vector<Knob> OptionTable() {
  std::vector<Knob> table;
  registration::Options defaults;
  registration::VisitRegistrationOptions(defaults, [&table](const char* name, const auto& field, const char* help) {
    using T = std::decay_t<decltype(field)>;
    Knob knob{name, py::none(), help, {}};
    if constexpr (std::is_enum_v<T>) {
      knob.default_value = py::str(registration::ChoiceName(field));
      for (const auto& [choice, unused] : registration::Choices<T>::All()) knob.choices.push_back(choice);
    } else {
      knob.default_value = py::cast(field);
    }
    table.push_back(std::move(knob));
  });
  return table;
}

std::vector<registration::Camera> CamerasFromArrays(const py::array_t<double, py::array::c_style | py::array::forcecast>& K,
                                                    const RowMatrix& image_sizes) {
  if (K.ndim() != 3 || K.shape(1) != 3 || K.shape(2) != 3) {
    throw std::invalid_argument("registration: intrinsics must have shape (cameras, 3, 3)");
  }
  if (image_sizes.rows() != K.shape(0) || image_sizes.cols() != 2) {
    throw std::invalid_argument("registration: image_sizes must have shape (cameras, 2)");
  }
  RequireFiniteValues(K, "registration: intrinsics");
  const auto k = K.unchecked<3>();
  std::vector<registration::Camera> cameras(K.shape(0));
  for (py::ssize_t c = 0; c < K.shape(0); ++c) {
    cameras[c].K = {k(c, 0, 0), k(c, 1, 1), k(c, 0, 2), k(c, 1, 2), k(c, 0, 1)};
    cameras[c].width = image_sizes(c, 0);
    cameras[c].height = image_sizes(c, 1);
  }
  return cameras;
}

py::array_t<bool> BoolArray(const std::vector<bool>& values) {
  py::array_t<bool> out(static_cast<py::ssize_t>(values.size()));
  auto view = out.mutable_unchecked<1>();
  for (size_t i = 0; i < values.size(); ++i) view(i) = values[i];
  return out;
}

// The registration's step results as read-only classes, each field documented where
// the struct is (registration/reconstruction.h).
void RegisterStepResults(py::module_& m) {
  using namespace registration;
  py::class_<PairCandidate>(m, "PairCandidate", "A camera pair that could start the registration.")
      .def_readonly("camera1", &PairCandidate::camera1)
      .def_readonly("camera2", &PairCandidate::camera2)
      .def_readonly("score1", &PairCandidate::score1, "view score of the common points in camera1")
      .def_readonly("score2", &PairCandidate::score2, "view score of the common points in camera2")
      .def_readonly("common_points", &PairCandidate::common_points)
      .def_readonly("connected_cameras", &PairCandidate::connected_cameras,
                    "size of the group of cameras connected to this pair");
  py::class_<InitialPairResult>(m, "InitialPairResult", "How a pair's initialisation went.")
      .def_readonly("success", &InitialPairResult::success)
      .def_readonly("reason", &InitialPairResult::reason, "why it failed")
      .def_readonly("homography_inliers", &InitialPairResult::homography_inliers)
      .def_readonly("median_parallax_deg", &InitialPairResult::median_parallax_deg)
      .def_readonly("solutions", &InitialPairResult::solutions,
                    "decompositions with the points in front of both cameras")
      .def_readonly("third_camera", &InitialPairResult::third_camera,
                    "camera used to pick between two solutions; -1 if both were refined")
      .def_readonly("normal_agreement", &InitialPairResult::normal_agreement,
                    "cosine between the chosen normal and the third camera's")
      .def_readonly("points", &InitialPairResult::points);
  py::class_<NextCameraCandidate>(m, "NextCameraCandidate", "The unregistered camera to register next.")
      .def_readonly("camera", &NextCameraCandidate::camera, "-1: none left")
      .def_readonly("score", &NextCameraCandidate::score)
      .def_readonly("points", &NextCameraCandidate::points, "observations of reconstructed points");
  py::class_<RegisterResult>(m, "RegisterResult", "How a camera's registration went.")
      .def_readonly("success", &RegisterResult::success)
      .def_readonly("reason", &RegisterResult::reason, "why it failed")
      .def_readonly("correspondences", &RegisterResult::correspondences)
      .def_readonly("inliers", &RegisterResult::inliers)
      .def_readonly("mean_error_px", &RegisterResult::mean_error_px, "after refinement, over the inliers");
  py::class_<AdjustResult>(m, "AdjustResult", "A bundle adjustment's figures.")
      .def_readonly("initial_cost", &AdjustResult::initial_cost)
      .def_readonly("final_cost", &AdjustResult::final_cost)
      .def_readonly("iterations", &AdjustResult::iterations)
      .def_readonly("termination", &AdjustResult::termination)
      .def_readonly("cameras", &AdjustResult::cameras)
      .def_readonly("points", &AdjustResult::points)
      .def_readonly("observations", &AdjustResult::observations)
      .def_readonly("solve_time_s", &AdjustResult::solve_time_s);
  py::class_<ReliefTest>(m, "ReliefTest", "Whether the floor was found uneven.")
      .def_readonly("tested", &ReliefTest::tested)
      .def_readonly("detected", &ReliefTest::detected)
      .def_readonly("parallax", &ReliefTest::parallax, "the projector's apex is refined with the relief")
      .def_readonly("nodes", &ReliefTest::nodes)
      .def_readonly("gain_chi2", &ReliefTest::gain_chi2, "chi-square of the observations the relief takes off")
      .def_readonly("threshold_chi2", &ReliefTest::threshold_chi2,
                    "the gain a flat floor's shared detection errors stay below: 4 times the 99.9 % quantile of "
                    "chi-square with `nodes` degrees of freedom")
      .def_property_readonly("message", &ReliefTest::Describe, "the verdict and its figures ('' when not tested)");
  py::class_<RefineResult>(m, "RefineResult", "The final refinement's figures.")
      .def_readonly("rounds", &RefineResult::rounds)
      .def_readonly("changed", &RefineResult::changed, "observations whose inlier status changed, over all rounds")
      .def_readonly("removed", &RefineResult::removed, "inactive observations at the end")
      .def_readonly("planes_found", &RefineResult::planes_found, "planes found besides the main one (coplanar)")
      .def_readonly("relief", &RefineResult::relief)
      .def_readonly("last", &RefineResult::last, "the last round's bundle adjustment")
      .def_readonly("thresholds", &RefineResult::thresholds, "per camera, pixels")
      .def_readonly("seconds", &RefineResult::seconds, "wall time of the whole refinement")
      .def_readonly("covariance_seconds", &RefineResult::covariance_seconds, "of it, the covariance's");
  py::class_<RunSummary>(m, "RunSummary", "What Reconstruction.run did.")
      .def_readonly("initialized", &RunSummary::initialized)
      .def_readonly("initial_pair", &RunSummary::initial_pair)
      .def_readonly("initial", &RunSummary::initial)
      .def_readonly("refined", &RunSummary::refined);
}

}  // namespace

void register_registration(py::module_& m) {
  RegisterStepResults(m);
  using GIL = py::call_guard<py::gil_scoped_release>;
  py::class_<Reconstruction>(m, "Reconstruction", R"doc(Incremental registration state and its steps.

Reconstruction(intrinsics (C, 3, 3), image_sizes (C, 2), num_points, camera_index (N,),
point_index (N,), observed (N, 2) undistorted pixels, **options). Options are the fields
of calibproj.registration.driver.RegistrationOptions.)doc")
      .def(py::init([](const py::array_t<double, py::array::c_style | py::array::forcecast>& K,
                       const RowMatrix& image_sizes, int num_points, const Eigen::VectorXi& camera_index,
                       const Eigen::VectorXi& point_index, const RowMatrix& observed, const py::kwargs& kwargs) {
             if (observed.cols() != 2 && observed.size() > 0) {
               throw std::invalid_argument("registration: observed must have shape (N, 2)");
             }
             ba::PixelMatrix pixels(observed.rows(), 2);
             if (observed.size() > 0) pixels = observed;
             return Reconstruction(CamerasFromArrays(K, image_sizes), num_points, camera_index, point_index, pixels,
                                   OptionsFromKwargs(kwargs));
           }),
           py::arg("intrinsics"), py::arg("image_sizes"), py::arg("num_points"), py::arg("camera_index"),
           py::arg("point_index"), py::arg("observed"))
      .def("rank_initial_pairs", &Reconstruction::RankInitialPairs, "Camera pairs with enough common points, best first (maximising both view scores).")
      .def("initialize", [](Reconstruction& r, int c1, int c2) {
             registration::InitialPairResult result;
             { py::gil_scoped_release release; result = r.Initialize(c1, c2); }
             return result;
           }, py::arg("camera1"), py::arg("camera2"),
           "Homography, decomposition, disambiguation, initial plane and points of a pair.")
      .def("choose_next_camera", &Reconstruction::ChooseNextCamera,
           "Unregistered camera with the best view score on reconstructed points (camera -1: none).")
      .def("register_camera", [](Reconstruction& r, int c) {
             registration::RegisterResult result;
             { py::gil_scoped_release release; result = r.RegisterCamera(c); }
             return result;
           }, py::arg("camera"), "PnP RANSAC and refinement; a failure marks the camera failed.")
      .def("add_points", &Reconstruction::AddPoints, py::arg("camera"), GIL(),
           "Triangulate (FREE) or back-project (COPLANAR) the new points a registered camera sees.")
      .def("adjust", [](Reconstruction& r, bool final) {
             registration::AdjustResult result;
             { py::gil_scoped_release release; result = r.Adjust(final); }
             return result;
           }, py::arg("final") = false, "Bundle adjustment of all registered cameras and reconstructed points.")
      .def("outlier_thresholds", &Reconstruction::OutlierThresholds,
           "Per-camera reprojection thresholds max(outlier_threshold_px, factor * robust sigma).")
      .def("filter_outliers", py::overload_cast<>(&Reconstruction::FilterOutliers), GIL(),
           "Deactivate observations above the (noise-adaptive) reprojection threshold.")
      .def("filter_outliers", py::overload_cast<const std::vector<double>&>(&Reconstruction::FilterOutliers),
           py::arg("thresholds"), GIL(), "Deactivate observations above the given per-camera thresholds.")
      .def("refine", [](Reconstruction& r) {
             registration::RefineResult result;
             { py::gil_scoped_release release; result = r.Refine(); }
             return result;
           }, "Final bundle adjustment and outlier removal, repeated until nothing is removed.")
      .def("fail_unregistered", &Reconstruction::FailUnregistered, "Give every unregistered camera its reason.")
      .def("run", [](Reconstruction& r, const std::function<void(const std::string&)>& log) {
             registration::RunSummary summary;
             {
               py::gil_scoped_release release;
               summary = registration::Run(r, [&log](const std::string& message) {
                 if (!log) return;
                 py::gil_scoped_acquire acquire;
                 log(message);
               });
             }
             return summary;
           }, py::arg("log") = std::function<void(const std::string&)>(),
           "All steps in order, in C++ (the standalone executable's path).")
      .def_property_readonly("num_cameras", &Reconstruction::num_cameras)
      .def_property_readonly("num_points", &Reconstruction::num_points)
      .def_property_readonly("registered", [](const Reconstruction& r) {
             std::vector<bool> v(r.num_cameras());
             for (int c = 0; c < r.num_cameras(); ++c) v[c] = r.registered(c);
             return BoolArray(v);
           })
      .def_property_readonly("failure_reasons", &Reconstruction::failure_reasons)
      .def_property_readonly("poses", &Reconstruction::poses)
      .def_property_readonly("points", &Reconstruction::points)
      .def_property_readonly("reconstructed", [](const Reconstruction& r) { return BoolArray(r.reconstructed()); })
      .def_property_readonly("active", [](const Reconstruction& r) { return BoolArray(r.active()); })
      .def_property_readonly("plane", [](const Reconstruction& r) { return Eigen::VectorXd(r.plane()); })
      .def_property_readonly("gauge_camera", &Reconstruction::gauge_camera)
      .def_property_readonly("registration_order", &Reconstruction::registration_order)
      .def("residuals", &Reconstruction::Residuals, "Residuals (N, 2) of the active observations, NaN elsewhere.")
      .def("set_projector", [](Reconstruction& r, const RowMatrix& pixels, double width, double height,
                               const std::vector<double>& marker_sides) {
             if (pixels.cols() != 2 && pixels.size() > 0) throw std::invalid_argument("projector pixels: expected shape (N, 2)");
             ba::PixelMatrix p(pixels.rows(), 2);
             if (pixels.size() > 0) p = pixels;
             r.SetProjector(p, width, height, marker_sides);
           }, py::arg("pixels"), py::arg("width"), py::arg("height"), py::arg("marker_sides") = std::vector<double>{},
           "Projector pixel (N, 2) of every point, NaN where unknown, and the projector's image size; optionally per\n"
           "point the side of the largest marker drawn at it (projector px, NaN unknown), which groups the\n"
           "projector's noise.")
      .def("set_lens_uncertainty", [](Reconstruction& r, int camera, const Eigen::Matrix3d& K,
                                      const std::vector<double>& distortion, const Eigen::MatrixXd& covariance) {
             if (covariance.rows() != selfcal::kLensSize || covariance.cols() != selfcal::kLensSize) {
               throw std::invalid_argument("lens covariance: expected shape (8, 8)");
             }
             registration::LensUncertainty u;
             selfcal::LensOf(K, distortion.data(), static_cast<int>(distortion.size()), u.lens, &u.shape);
             u.covariance = covariance;
             r.SetLensUncertainty(camera, u);
           }, py::arg("camera"), py::arg("K"), py::arg("distortion"), py::arg("covariance"),
           "The refined intrinsics (K, OpenCV distortion) the camera's observations were undistorted with, and\n"
           "the covariance (8, 8) of its lens [f, cx, cy, k1, k2, p1, p2, k3]: the poses' covariance then takes\n"
           "it in.")
      .def("set_lens_cross_covariances", &Reconstruction::SetLensCrossCovariances, py::arg("cameras"), py::arg("joint"),
           "How the lenses of these cameras (each given by set_lens_uncertainty first) err together: their joint\n"
           "covariance (8n, 8n), the k-th camera in rows and columns 8k to 8k + 7, whose diagonal blocks are the\n"
           "lenses' own.")
      .def("projector_prediction", [](const Reconstruction& r, int point) -> py::object {
             Eigen::Vector3d X;
             if (!r.ProjectorPrediction(point, &X)) return py::none();
             return py::cast(Eigen::VectorXd(X));
           }, py::arg("point"), "Where the projector draws the point (on the plane projected_plane names), or None.")
      .def("projected_plane", &Reconstruction::ProjectedPlane, py::arg("point"),
           "The plane the projector draws the point on: a raised surface (a table top) whose reconstructed\n"
           "points surround its projector pixel, else the main plane (0); -1 without a projector pixel.")
      .def_property_readonly("point_planes", &Reconstruction::point_plane,
                             "Per point the plane it was placed on (0 the main plane, -1 off every plane or not placed).")
      .def_property_readonly("projector_lens", [](const Reconstruction& r) { return Eigen::VectorXd(r.projector_lens()); })
      .def_property_readonly("projector_centre", [](const Reconstruction& r) { return Eigen::VectorXd(r.projector_centre()); },
                             "the projector's optical centre where the floor's relief places it (NaN without a relief)")
      .def_property_readonly("projector_sigma_px", &Reconstruction::projector_sigma_px,
                             "Per group of points the projector maps' noise (projector px, NaN until estimated).")
      .def_property_readonly("projector_group_sides_px", &Reconstruction::projector_group_sides_px,
                             "Per group the side of the largest marker drawn at its points (NaN: not known).")
      .def_property_readonly("camera_sigma_px", &Reconstruction::camera_sigma_px)
      .def("view_score", &Reconstruction::ViewScore, py::arg("camera"))
      .def(
          "calibration",
          [](const Reconstruction& r, const std::vector<std::string>& camera_names,
             const std::vector<std::int64_t>& point_ids, const std::vector<formats::NamedText>& left_out,
             const std::string& model) {
            if (camera_names.size() != static_cast<size_t>(r.num_cameras())) {
              throw std::invalid_argument("camera_names: " + std::to_string(camera_names.size()) + " names for " +
                                          std::to_string(r.num_cameras()) + " cameras");
            }
            if (point_ids.size() != static_cast<size_t>(r.num_points())) {
              throw std::invalid_argument("point_ids: " + std::to_string(point_ids.size()) + " ids for " +
                                          std::to_string(r.num_points()) + " points");
            }
            return formats::FromRegistration(registration::Summarize(r), camera_names, point_ids, left_out, model);
          },
          py::arg("camera_names"), py::arg("point_ids"), py::arg("left_out"), py::arg("model"),
          "The Calibration of the current state in the floor frame: camera_names and point_ids name the "
          "registration's cameras and points, left_out [(camera, reason)] the cameras that failed before it.");

  m.def(
      "view_score",
      [](const RowMatrix& pixels, double width, double height, int levels) {
        if (pixels.cols() != 2 && pixels.size() > 0) throw std::invalid_argument("pixels: expected shape (N, 2)");
        registration::VisibilityPyramid pyramid(levels, width, height);
        for (int i = 0; i < pixels.rows(); ++i) pyramid.Add(pixels(i, 0), pixels(i, 1));
        return py::make_tuple(pyramid.Score(), pyramid.MaxScore());
      },
      py::arg("pixels"), py::arg("width"), py::arg("height"), py::arg("levels") = 3,
      "(score, max score) of the COLMAP visibility pyramid of the pixels (N, 2).");
  m.def(
      "check_options", [](const py::kwargs& kwargs) { OptionsFromKwargs(kwargs); },
      "Raises ValueError naming the first registration option (keyword) that is unknown or out of range.");
  m.def("option_table", &OptionTable,
        "Every registration knob as a Knob (name, default, help, choices), in order: the one declaration "
        "calibproj.registration.driver.RegistrationOptions and both command lines are made from.");
}

}  // namespace calibproj::bindings
