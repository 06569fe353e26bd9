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
py::list OptionTable() {
  py::list table;
  registration::Options defaults;
  registration::VisitRegistrationOptions(defaults, [&table](const char* name, const auto& field, const char* help) {
    using T = std::decay_t<decltype(field)>;
    py::dict entry;
    entry["name"] = name;
    entry["help"] = help;
    if constexpr (std::is_enum_v<T>) {
      entry["default"] = registration::ChoiceName(field);
      py::list choices;
      for (const auto& [choice, unused] : registration::Choices<T>::All()) choices.append(choice);
      entry["choices"] = choices;
    } else {
      entry["default"] = field;
    }
    table.append(entry);
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

py::dict ToDict(const registration::PairCandidate& p) {
  py::dict d;
  d["camera1"] = p.camera1; d["camera2"] = p.camera2; d["score1"] = p.score1; d["score2"] = p.score2;
  d["common_points"] = p.common_points; d["connected_cameras"] = p.connected_cameras;
  return d;
}

py::dict ToDict(const registration::InitialPairResult& r) {
  py::dict d;
  d["success"] = r.success; d["reason"] = r.reason; d["homography_inliers"] = r.homography_inliers;
  d["median_parallax_deg"] = r.median_parallax_deg;
  d["solutions"] = r.solutions; d["third_camera"] = r.third_camera; d["normal_agreement"] = r.normal_agreement;
  d["points"] = r.points;
  return d;
}

py::dict ToDict(const registration::NextCameraCandidate& n) {
  py::dict d;
  d["camera"] = n.camera; d["score"] = n.score; d["points"] = n.points;
  return d;
}

py::dict ToDict(const registration::RegisterResult& r) {
  py::dict d;
  d["success"] = r.success; d["reason"] = r.reason; d["correspondences"] = r.correspondences;
  d["inliers"] = r.inliers; d["mean_error_px"] = r.mean_error_px;
  return d;
}

py::dict ToDict(const registration::AdjustResult& r) {
  py::dict d;
  d["initial_cost"] = r.initial_cost; d["final_cost"] = r.final_cost; d["iterations"] = r.iterations;
  d["termination"] = r.termination; d["cameras"] = r.cameras; d["points"] = r.points;
  d["observations"] = r.observations; d["solve_time_s"] = r.solve_time_s;
  return d;
}

py::dict ToDict(const registration::ReliefTest& t) {
  py::dict d;
  d["tested"] = t.tested; d["detected"] = t.detected; d["nodes"] = t.nodes;
  d["gain_chi2"] = t.gain_chi2; d["threshold_chi2"] = t.threshold_chi2; d["message"] = t.Describe();
  return d;
}

py::dict ToDict(const registration::RefineResult& r) {
  py::dict d;
  d["rounds"] = r.rounds; d["changed"] = r.changed; d["removed"] = r.removed; d["planes_found"] = r.planes_found; d["last"] = ToDict(r.last); d["thresholds"] = r.thresholds;
  d["seconds"] = r.seconds; d["covariance_seconds"] = r.covariance_seconds;
  d["relief"] = ToDict(r.relief);
  return d;
}


}  // namespace

void register_registration(py::module_& m) {
  using GIL = py::call_guard<py::gil_scoped_release>;
  py::class_<Reconstruction>(m, "Reconstruction", R"doc(Incremental registration state and its steps.

Reconstruction(intrinsics (C, 3, 3), image_sizes (C, 2), num_points, camera_index (N,),
point_index (N,), observed (N, 2) undistorted pixels, **options). Options are the fields
of calibproj.registration.RegistrationOptions.)doc")
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
      .def("rank_initial_pairs", [](const Reconstruction& r) {
             py::list out;
             for (const auto& p : r.RankInitialPairs()) out.append(ToDict(p));
             return out;
           }, "Camera pairs with enough common points, best first (maximising both view scores).")
      .def("initialize", [](Reconstruction& r, int c1, int c2) {
             registration::InitialPairResult result;
             { py::gil_scoped_release release; result = r.Initialize(c1, c2); }
             return ToDict(result);
           }, py::arg("camera1"), py::arg("camera2"),
           "Homography, decomposition, disambiguation, initial plane and points of a pair.")
      .def("choose_next_camera", [](const Reconstruction& r) { return ToDict(r.ChooseNextCamera()); },
           "Unregistered camera with the best view score on reconstructed points (camera -1: none).")
      .def("register_camera", [](Reconstruction& r, int c) {
             registration::RegisterResult result;
             { py::gil_scoped_release release; result = r.RegisterCamera(c); }
             return ToDict(result);
           }, py::arg("camera"), "PnP RANSAC and refinement; a failure marks the camera failed.")
      .def("add_points", &Reconstruction::AddPoints, py::arg("camera"), GIL(),
           "Triangulate (FREE) or back-project (COPLANAR) the new points a registered camera sees.")
      .def("adjust", [](Reconstruction& r, bool final) {
             registration::AdjustResult result;
             { py::gil_scoped_release release; result = r.Adjust(final); }
             return ToDict(result);
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
             return ToDict(result);
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
             py::dict d;
             d["initialized"] = summary.initialized;
             d["initial_pair"] = ToDict(summary.initial_pair);
             d["initial"] = ToDict(summary.initial);
             d["refined"] = ToDict(summary.refined);
             return d;
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
           }, py::arg("point"), "Where the projector draws the point on the main plane, or None.")
      .def_property_readonly("projector_lens", [](const Reconstruction& r) { return Eigen::VectorXd(r.projector_lens()); })
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
        "Every registration knob as {name, default, help[, choices]}, in order: the one declaration "
        "calibproj.registration.RegistrationOptions and both command lines are made from.");
}

}  // namespace calibproj::bindings
