// calibproj._core.uncertainty: the poses' joint covariance, what it means for
// triangulated points, and uncertainty.json.

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <limits>
#include <string>
#include <vector>

#include "calibproj/registration/pose_uncertainty.h"
#include "calibproj/uncertainty/triangulation.h"
#include "calibproj/uncertainty/volume_map.h"
#include "python_objects.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

using registration::PoseUncertainty;
using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// (covariance (N, 3, 3), its share from the poses (N, 3, 3), cameras per point): NaN
// covariances for a point fewer than two cameras see.
py::tuple Triangulation(const py::object& calibration, const py::dict& intrinsics, const RowMatrix& points,
                        double noise_px) {
  if (points.cols() != 3 && points.size() > 0) throw std::invalid_argument("points: expected shape (N, 3)");
  if (!(noise_px >= 0.0) || !std::isfinite(noise_px)) throw std::invalid_argument("noise_px: must be >= 0 and finite");
  const formats::Calibration core = CalibrationFromPython(calibration);
  const auto cameras = IntrinsicsFromPython(intrinsics);
  const uncertainty::UncertaintyModel model(core, cameras);
  const py::ssize_t n = points.rows();
  py::array_t<double> covariance({n, py::ssize_t{3}, py::ssize_t{3}}), from_poses({n, py::ssize_t{3}, py::ssize_t{3}});
  auto total = covariance.mutable_unchecked<3>();
  auto poses = from_poses.mutable_unchecked<3>();
  std::vector<std::vector<std::string>> seen(n);
  for (py::ssize_t p = 0; p < n; ++p) {
    const uncertainty::PointUncertainty u = model.Triangulation(points.row(p).transpose(), noise_px);
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        total(p, i, j) = u.determined ? u.covariance(i, j) : std::numeric_limits<double>::quiet_NaN();
        poses(p, i, j) = u.determined ? u.from_poses(i, j) : std::numeric_limits<double>::quiet_NaN();
      }
    }
    for (int c : u.cameras) seen[p].push_back(model.name(c));
  }
  return py::make_tuple(covariance, from_poses, seen);
}

// (N, 2, 2) covariance of each point's pixel in the camera from its pose alone; NaN
// where the camera does not see the point.
py::array_t<double> Projection(const py::object& calibration, const py::dict& intrinsics, const std::string& camera,
                               const RowMatrix& points) {
  if (points.cols() != 3 && points.size() > 0) throw std::invalid_argument("points: expected shape (N, 3)");
  const formats::Calibration core = CalibrationFromPython(calibration);
  const uncertainty::UncertaintyModel model(core, IntrinsicsFromPython(intrinsics));
  int index = -1;
  for (int c = 0; c < model.num_cameras(); ++c) {
    if (model.name(c) == camera) index = c;
  }
  if (index < 0) throw std::invalid_argument("camera " + camera + ": not in the pose covariance");
  const py::ssize_t n = points.rows();
  py::array_t<double> out({n, py::ssize_t{2}, py::ssize_t{2}});
  auto view = out.mutable_unchecked<3>();
  for (py::ssize_t p = 0; p < n; ++p) {
    const Eigen::Vector3d X = points.row(p).transpose();
    const bool seen = model.Sees(index, X);
    const Eigen::Matrix2d C = seen ? model.Projection(index, X) : Eigen::Matrix2d::Constant(std::nan(""));
    for (int i = 0; i < 2; ++i) {
      for (int j = 0; j < 2; ++j) view(p, i, j) = C(i, j);
    }
  }
  return out;
}

}  // namespace

void register_uncertainty(py::module_& m) {
  py::class_<PoseUncertainty>(m, "PoseUncertainty",
                              "The registered cameras' joint pose covariance from the final bundle adjustment, in "
                              "the calibration's frame and unit, relative to the reference camera.")
      .def(py::init([](std::vector<std::string> cameras, std::string reference, Eigen::MatrixXd covariance,
                       std::vector<double> noise_px, std::vector<int> lens_block) {
             PoseUncertainty out{std::move(cameras), std::move(reference), std::move(covariance), std::move(noise_px),
                                 std::move(lens_block)};
             out.Check();
             return out;
           }),
           py::arg("cameras"), py::arg("reference"), py::arg("covariance"), py::arg("noise_px"),
           py::arg("lens_block") = std::vector<int>{})
      .def_readonly("cameras", &PoseUncertainty::cameras, "the registered cameras, in the covariance's order")
      .def_readonly("reference", &PoseUncertainty::reference,
                    "the camera whose pose and distance to the floor were held (its rows are zero)")
      .def_readonly("covariance", &PoseUncertainty::covariance,
                    "(6C + 8L, 6C + 8L): per camera [dtheta (rad), dt] of its world-to-camera pose, R = Exp(dtheta) "
                    "R_hat; then per refined lens [f, cx, cy, k1, k2, p1, p2, k3]")
      .def_readonly("lens_block", &PoseUncertainty::lens_block,
                    "per camera the index of its refined lens's block (-1: intrinsics taken as exact); empty: none")
      .def_readonly("noise_px", &PoseUncertainty::noise_px, "per camera, its centres' noise (px, 1 sigma per coordinate)")
      .def("named", &PoseUncertainty::Named, py::arg("names"),
           "the same with cameras given by index renamed to names[index]")
      .def(py::pickle(
          [](const PoseUncertainty& u) {
            return py::make_tuple(u.cameras, u.reference, u.covariance, u.noise_px, u.lens_block);
          },
          [](const py::tuple& state) {
            if (state.size() != 5) throw std::invalid_argument("PoseUncertainty: not a pickled PoseUncertainty");
            PoseUncertainty out{state[0].cast<std::vector<std::string>>(), state[1].cast<std::string>(),
                                state[2].cast<Eigen::MatrixXd>(), state[3].cast<std::vector<double>>(),
                                state[4].cast<std::vector<int>>()};
            out.Check();
            return out;
          }));
  m.def("triangulation", &Triangulation, py::arg("calibration"), py::arg("intrinsics"), py::arg("points"),
        py::arg("noise_px") = 0.0,
        "Per point (N, 3) of the calibration's frame: the covariance (N, 3, 3) of the point triangulated from the "
        "cameras that see it (each with its own noise, or noise_px > 0 for all), its share from the poses' "
        "uncertainty, and the cameras; NaN for a point fewer than two cameras see.");
  m.def("projection", &Projection, py::arg("calibration"), py::arg("intrinsics"), py::arg("camera"), py::arg("points"),
        "Per point (N, 3): covariance (N, 2, 2, px^2) of its pixel in the camera from the camera's pose uncertainty; "
        "NaN where the camera does not see it.");
  m.def(
      "write",
      [](const std::filesystem::path& directory, const py::object& calibration, const py::dict& intrinsics) {
        const formats::Calibration core = CalibrationFromPython(calibration);
        const auto cameras = IntrinsicsFromPython(intrinsics);
        py::gil_scoped_release release;
        return uncertainty::WriteUncertainty(directory, core, cameras);
      },
      py::arg("directory"), py::arg("calibration"), py::arg("intrinsics"),
      "Writes uncertainty.json into the folder when the calibration carries a pose covariance; False when not.");
  m.def("read_pose_uncertainty", &uncertainty::ReadPoseUncertainty, py::arg("directory"),
        "The joint pose covariance a results folder's uncertainty.json holds (InputError naming the file).");
  m.def(
      "stored_pose_uncertainty",
      [](const std::filesystem::path& directory, const py::object& calibration) {
        std::string warning;
        const auto stored = uncertainty::StoredPoseUncertainty(directory, CalibrationFromPython(calibration), &warning);
        return py::make_tuple(stored.empty() ? py::none() : py::cast(stored), warning);
      },
      py::arg("directory"), py::arg("calibration"),
      "(PoseUncertainty or None, warning): the covariance the results folder's uncertainty.json stores for this\n"
      "calibration; None with why when it is unreadable or of other cameras (an empty warning: no such file).");
  m.attr("FILE") = uncertainty::kUncertaintyFile;
}

}  // namespace calibproj::bindings
