// Bindings of calibproj::selfcal: numpy arrays in, its Result out.

#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "calibproj/selfcal/planar_cost.h"
#include "calibproj/selfcal/self_calibration.h"
#include "checks.h"
#include "convert.h"
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

}  // namespace

void register_selfcal(py::module_& m) {
  m.attr("lens_size") = selfcal::kLensSize;
  RegisterResult(m);
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
