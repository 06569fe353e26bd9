#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>

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
}

}  // namespace calibproj::bindings
