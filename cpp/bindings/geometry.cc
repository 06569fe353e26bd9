#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <Eigen/Geometry>
#include <cmath>
#include <string>
#include <vector>

#include "calibproj/geometry/homography.h"
#include "calibproj/geometry/similarity.h"
#include "calibproj/geometry/triangulation.h"
#include "checks.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

void register_geometry(py::module_& m) {
  py::class_<geometry::Similarity3>(m, "Similarity3", "dst ~= scale * R @ src + t")
      .def_readonly("scale", &geometry::Similarity3::scale)
      .def_readonly("R", &geometry::Similarity3::R)
      .def_readonly("t", &geometry::Similarity3::t);

  m.def(
      "estimate_similarity",
      [](const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>& src,
         const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>& dst) {
        return geometry::EstimateSimilarity(src.transpose(), dst.transpose());
      },
      py::arg("src"), py::arg("dst"),
      "Least-squares Sim(3) (Umeyama) mapping src (N, 3) onto dst (N, 3).");

  m.def(
      "triangulate_linear",
      [](const py::array_t<double, py::array::c_style | py::array::forcecast>& R,
         const py::array_t<double, py::array::c_style | py::array::forcecast>& t,
         const py::array_t<double, py::array::c_style | py::array::forcecast>& rays,
         const py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>& point_index, int num_points) {
        const py::ssize_t n = point_index.size();
        if (R.ndim() != 3 || R.shape(0) != n || R.shape(1) != 3 || R.shape(2) != 3 || t.ndim() != 2 ||
            t.shape(0) != n || t.shape(1) != 3 || rays.ndim() != 2 || rays.shape(0) != n || rays.shape(1) != 2) {
          throw py::value_error("triangulate_linear: expected R (N, 3, 3), t (N, 3), rays (N, 2) for N = " +
                                std::to_string(n) + " observations");
        }
        RequireCount(num_points, 0, limits::kMaxPoints, "triangulate_linear: num_points");
        RequireFiniteValues(R, "triangulate_linear: R");
        RequireFiniteValues(t, "triangulate_linear: t");
        RequireFiniteValues(rays, "triangulate_linear: rays");
        std::vector<std::vector<geometry::View>> views(num_points);
        const auto r = R.unchecked<3>();
        const auto tt = t.unchecked<2>();
        const auto x = rays.unchecked<2>();
        const auto p = point_index.unchecked<1>();
        for (py::ssize_t k = 0; k < n; ++k) {
          if (p(k) < 0 || p(k) >= num_points) {
            throw py::value_error("triangulate_linear: point index " + std::to_string(p(k)) + " out of range");
          }
          geometry::View view;
          for (int i = 0; i < 3; ++i) {
            for (int j = 0; j < 3; ++j) view.R(i, j) = r(k, i, j);
            view.t(i) = tt(k, i);
          }
          view.ray = Eigen::Vector2d(x(k, 0), x(k, 1));
          views[p(k)].push_back(view);
        }
        py::array_t<double> out({static_cast<py::ssize_t>(num_points), static_cast<py::ssize_t>(3)});
        auto o = out.mutable_unchecked<2>();
        {
          py::gil_scoped_release release;
          for (int q = 0; q < num_points; ++q) {
            Eigen::Vector3d X = Eigen::Vector3d::Constant(std::nan(""));
            if (views[q].size() >= 2) {
              const Eigen::Vector4d h = geometry::TriangulateHomogeneous(views[q]);
              if (std::abs(h(3)) >= 1e-12) X = h.hnormalized();
            }
            for (int i = 0; i < 3; ++i) o(q, i) = X(i);
          }
        }
        return out;
      },
      py::arg("R"), py::arg("t"), py::arg("rays"), py::arg("point_index"), py::arg("num_points"),
      "Linear (DLT) triangulation of every point from its views: per observation the view's pose R (N, 3, 3), "
      "t (N, 3) and normalised ray (N, 2), and its point index (N,); returns (num_points, 3), NaN for points "
      "with fewer than two views or at infinity.");
  m.def(
      "estimate_homography",
      [](const geometry::Points2& x1, const geometry::Points2& x2, double threshold_px, double focal1, double focal2,
         int max_iterations, std::uint64_t seed) {
        geometry::HomographyRansacOptions options;
        options.threshold_px = threshold_px;
        options.focal1 = focal1;
        options.focal2 = focal2;
        options.max_iterations = max_iterations;
        options.seed = seed;
        geometry::HomographyEstimate estimate;
        {
          py::gil_scoped_release release;
          estimate = geometry::EstimateHomographyRansac(x1, x2, options);
        }
        return py::make_tuple(estimate.success, estimate.H, estimate.inliers);
      },
      py::arg("x1"), py::arg("x2"), py::arg("threshold_px") = 3.0, py::arg("focal1") = 1.0, py::arg("focal2") = 1.0,
      py::arg("max_iterations") = 2000, py::arg("seed") = 0,
      "(success, H, inliers): RANSAC homography x2 ~ H x1 between normalised coordinates (N, 2); the threshold "
      "is in pixels of each camera (focal1, focal2).");
  m.def(
      "decompose_homography",
      [](const Eigen::Matrix3d& H, const geometry::Points2& x1, const geometry::Points2& x2) {
        py::list out;
        for (const auto& motion : geometry::DecomposeHomography(H, x1, x2)) {
          out.append(py::make_tuple(motion.R, motion.t, motion.n));
        }
        return out;
      },
      py::arg("H"), py::arg("x1"), py::arg("x2"),
      "[(R, t, n)]: decompositions of H = R + t n^T (plane n . X = 1 in camera 1) that put the points in front.");
}

}  // namespace calibproj::bindings
