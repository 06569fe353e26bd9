#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "calibproj/geometry/homography.h"
#include "calibproj/geometry/similarity.h"
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
