// Bindings of calibproj::detect: numpy images in, (ids, corners) numpy arrays out.

#include <numeric>
#include <optional>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <stdexcept>
#include <string>

#include "calibproj/detect/floor_consistency.h"
#include "calibproj/detect/marker_centre.h"
#include "calibproj/detect/marker_detector.h"
#include "calibproj/detect/marker_family.h"
#include "checks.h"
#include "images.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

using detect::Quad;

py::array_t<double> CornersArray(const std::vector<Quad>& corners) {
  py::array_t<double> out({static_cast<py::ssize_t>(corners.size()), py::ssize_t{4}, py::ssize_t{2}});
  auto view = out.mutable_unchecked<3>();
  for (std::size_t i = 0; i < corners.size(); ++i) {
    for (int k = 0; k < 4; ++k) {
      view(i, k, 0) = corners[i][k].x;
      view(i, k, 1) = corners[i][k].y;
    }
  }
  return out;
}

std::vector<Quad> QuadsFromArray(const py::array_t<double, py::array::c_style | py::array::forcecast>& corners) {
  if (corners.ndim() != 3 || corners.shape(1) != 4 || corners.shape(2) != 2) {
    throw std::invalid_argument("corners: expected an array of shape (N, 4, 2)");
  }
  const auto view = corners.unchecked<3>();
  std::vector<Quad> quads(corners.shape(0));
  for (py::ssize_t i = 0; i < corners.shape(0); ++i) {
    for (int k = 0; k < 4; ++k) quads[i][k] = cv::Point2d(view(i, k, 0), view(i, k, 1));
  }
  return quads;
}

py::tuple DetectionsTuple(const detect::Detections& found) {
  py::array_t<int32_t> ids(static_cast<py::ssize_t>(found.size()));
  std::copy(found.ids.begin(), found.ids.end(), ids.mutable_data());
  return py::make_tuple(ids, CornersArray(found.corners));
}

void RegisterRefinement(py::module_& m) {
  py::enum_<detect::CornerRefinement>(m, "CornerRefinement", "How corners are refined (see corner_refinement.h)")
      .value("none", detect::CornerRefinement::kNone)
      .value("subpix", detect::CornerRefinement::kSubpix)
      .value("edges", detect::CornerRefinement::kEdges);

  using Options = detect::CornerRefinementOptions;
  py::class_<Options>(m, "CornerRefinementOptions", "Corner refinement options (see corner_refinement.h)")
      .def(py::init<>())
      .def_readwrite("method", &Options::method)
      .def_readwrite("window_fraction", &Options::window_fraction)
      .def_readwrite("window_min_px", &Options::window_min_px)
      .def_readwrite("window_max_px", &Options::window_max_px)
      .def_readwrite("max_iterations", &Options::max_iterations)
      .def_readwrite("epsilon_px", &Options::epsilon_px)
      .def_readwrite("edge_search_fraction", &Options::edge_search_fraction)
      .def_readwrite("edge_spacing_px", &Options::edge_spacing_px)
      .def_readwrite("edge_min_samples", &Options::edge_min_samples)
      .def_readwrite("edge_end_margin", &Options::edge_end_margin)
      .def_readwrite("edge_min_contrast", &Options::edge_min_contrast)
      .def_readwrite("edge_passes", &Options::edge_passes)
      .def("check", &Options::Check, "Raise ValueError naming the first bad field.");
}

void RegisterOptions(py::module_& m) {
  RegisterRefinement(m);
  py::class_<detect::ArucoOptions>(m, "ArucoOptions", "ArUco detection options (see aruco_detector.h)")
      .def(py::init<>())
      .def_readwrite("inverted", &detect::ArucoOptions::inverted)
      .def_readwrite("min_marker_perimeter_rate", &detect::ArucoOptions::min_marker_perimeter_rate)
      .def_readwrite("max_marker_perimeter_rate", &detect::ArucoOptions::max_marker_perimeter_rate)
      .def_readwrite("adaptive_thresh_win_size_min", &detect::ArucoOptions::adaptive_thresh_win_size_min)
      .def_readwrite("adaptive_thresh_win_size_max", &detect::ArucoOptions::adaptive_thresh_win_size_max)
      .def_readwrite("adaptive_thresh_win_size_step", &detect::ArucoOptions::adaptive_thresh_win_size_step)
      .def_readwrite("adaptive_thresh_constant", &detect::ArucoOptions::adaptive_thresh_constant)
      .def_readwrite("thresh_constant_contrast_share", &detect::ArucoOptions::thresh_constant_contrast_share)
      .def_readwrite("min_thresh_constant", &detect::ArucoOptions::min_thresh_constant)
      .def_readwrite("error_correction_rate", &detect::ArucoOptions::error_correction_rate)
      .def_readwrite("perspective_remove_pixel_per_cell", &detect::ArucoOptions::perspective_remove_pixel_per_cell)
      .def_readwrite("perspective_remove_ignored_margin_per_cell",
                     &detect::ArucoOptions::perspective_remove_ignored_margin_per_cell)
      .def_readwrite("refinement", &detect::ArucoOptions::refinement)
      .def("check", &detect::ArucoOptions::Check, "Raise ValueError naming the first bad field.");

  py::class_<detect::AprilTagOptions>(m, "AprilTagOptions", "AprilTag detection options (see apriltag_detector.h)")
      .def(py::init<>())
      .def_readwrite("inverted", &detect::AprilTagOptions::inverted)
      .def_readwrite("quad_decimate", &detect::AprilTagOptions::quad_decimate)
      .def_readwrite("quad_sigma", &detect::AprilTagOptions::quad_sigma)
      .def_readwrite("nthreads", &detect::AprilTagOptions::nthreads)
      .def_readwrite("refine_edges", &detect::AprilTagOptions::refine_edges)
      .def_readwrite("decode_sharpening", &detect::AprilTagOptions::decode_sharpening)
      .def_readwrite("max_hamming", &detect::AprilTagOptions::max_hamming)
      .def_readwrite("min_white_black_diff", &detect::AprilTagOptions::min_white_black_diff)
      .def_readwrite("refinement", &detect::AprilTagOptions::refinement)
      .def("check", &detect::AprilTagOptions::Check, "Raise ValueError naming the first bad field.");
}

void RegisterFamilies(py::module_& m) {
  m.def("family_specs", &detect::MarkerFamilySpecs, "Every marker family spec this build accepts.");
  using detect::MarkerFamilyInfo;
  py::class_<MarkerFamilyInfo>(m, "MarkerFamilyInfo", "What a marker family is made of.")
      .def_readonly("spec", &MarkerFamilyInfo::spec, "canonical spec, e.g. aruco:4X4_50")
      .def_readonly("system", &MarkerFamilyInfo::system, "aruco or apriltag")
      .def_readonly("name", &MarkerFamilyInfo::name, "the family name without the system")
      .def_readonly("id_count", &MarkerFamilyInfo::id_count, "number of ids (0 .. id_count - 1)")
      .def_property_readonly(
          "grid_cells", [](const MarkerFamilyInfo& f) { return f.geometry.grid_cells; },
          "side of the drawn marker in modules (cells), border included")
      .def_property_readonly(
          "quad_cells", [](const MarkerFamilyInfo& f) { return f.geometry.quad_cells; },
          "side in modules of the square whose corners the detector returns (smaller than grid_cells for "
          "AprilTags with the border inside, such as tagStandard41h12); both squares share the marker's centre")
      .def("__repr__", [](const MarkerFamilyInfo& f) { return "MarkerFamilyInfo(" + f.spec + ")"; });
  m.def(
      "family_info", &detect::DescribeMarkerFamily,
      py::arg("spec"),
      "Canonical spec, system, name, number of ids, side of the drawn grid and of the "
      "detected square (cells) of a marker family. ValueError for an unknown family.");
  m.def(
      "marker_bits",
      [](const std::string& spec, int id) {
        const cv::Mat bits = detect::MarkerBits(detect::ParseMarkerFamily(spec), id);
        py::array_t<uint8_t> out({bits.rows, bits.cols});
        for (int row = 0; row < bits.rows; ++row) {
          std::copy(bits.ptr<uint8_t>(row), bits.ptr<uint8_t>(row) + bits.cols, out.mutable_data(row, 0));
        }
        return out;
      },
      py::arg("spec"), py::arg("id"),
      "Cells of marker `id` as a square uint8 array of 0 (black) and 1 (white), as printed "
      "black on white.");
  m.def(
      "marker_centres",
      [](const py::array_t<double, py::array::c_style | py::array::forcecast>& corners) {
        const auto centres = detect::MarkerCentres(QuadsFromArray(corners));
        py::array_t<double> out({static_cast<py::ssize_t>(centres.size()), py::ssize_t{2}});
        auto view = out.mutable_unchecked<2>();
        for (std::size_t i = 0; i < centres.size(); ++i) {
          view(i, 0) = centres[i].x;
          view(i, 1) = centres[i].y;
        }
        return out;
      },
      py::arg("corners"),
      "Marker centres (N, 2): intersections of the diagonals of corners (N, 4, 2). "
      "NaN for a degenerate quad.");
  m.def(
      "check_floor_consistency",
      [](const py::array_t<double, py::array::c_style | py::array::forcecast>& projector,
         const py::array_t<double, py::array::c_style | py::array::forcecast>& image, double threshold_px,
         int min_points, double min_share, const std::optional<std::vector<int>>& positions, int min_positions,
         int max_surfaces, int local_neighbours, double local_sigmas, double min_local_px) {
        const auto points = [](const py::array_t<double, py::array::c_style | py::array::forcecast>& a,
                               const char* name) {
          RequireShape(a, {-1, 2}, name);
          std::vector<cv::Point2d> out(static_cast<std::size_t>(a.shape(0)));
          for (std::size_t i = 0; i < out.size(); ++i) out[i] = cv::Point2d(a.at(i, 0), a.at(i, 1));
          return out;
        };
        detect::ConsistencyOptions options;
        options.threshold_px = threshold_px;
        options.min_points = min_points;
        options.min_share = min_share;
        options.min_positions = min_positions;
        options.max_surfaces = max_surfaces;
        options.local_neighbours = local_neighbours;
        options.local_sigmas = local_sigmas;
        options.min_local_px = min_local_px;
        const std::vector<cv::Point2d> image_points = points(image, "image");
        // Without positions every detection counts as a marker position of its own.
        std::vector<int> position(image_points.size());
        std::iota(position.begin(), position.end(), 0);
        if (positions) position = *positions;
        const detect::ConsistencyResult result =
            detect::CheckFloorConsistency(points(projector, "projector"), image_points, position, options);
        py::array_t<bool> keep(static_cast<py::ssize_t>(result.keep.size()));
        std::copy(result.keep.begin(), result.keep.end(), keep.mutable_data());
        return py::make_tuple(keep, result.checked, result.problem);
      },
      py::arg("projector"), py::arg("image"), py::arg("threshold_px") = 3.0, py::arg("min_points") = 8,
      py::arg("min_share") = 0.3, py::arg("positions") = py::none(), py::arg("min_positions") = 3,
      py::arg("max_surfaces") = 3, py::arg("local_neighbours") = 8, py::arg("local_sigmas") = 5.0,
      py::arg("min_local_px") = 0.5,
      "(keep (N,) bool, checked, problem): detections (projector centre -> undistorted image centre) "
      "that agree with one RANSAC homography of the floor (or of one of max_surfaces surfaces); all "
      "dropped, with the problem, when too few agree with the first or they cover fewer than "
      "min_positions marker positions (positions: per detection, its marker's grid cell; None: all "
      "distinct); all kept unchecked below min_points. Then each kept one whose residual differs "
      "from the median residual of its local_neighbours nearest other markers by more than "
      "local_sigmas robust sigmas and min_local_px is dropped (local_neighbours 0: not).");
}

}  // namespace

void register_detect(py::module_& m) {
  RegisterOptions(m);
  RegisterFamilies(m);

  py::class_<detect::MarkerDetector>(m, "MarkerDetector",
                                     "Detector for one marker family; build once, call detect() per image.")
      .def(py::init([](const std::string& spec, const detect::ArucoOptions& aruco,
                       const detect::AprilTagOptions& apriltag) {
             return std::make_unique<detect::MarkerDetector>(detect::ParseMarkerFamily(spec),
                                                             detect::DetectorOptions{aruco, apriltag});
           }),
           py::arg("spec"), py::arg("aruco") = detect::ArucoOptions(),
           py::arg("apriltag") = detect::AprilTagOptions())
      .def_property_readonly("spec", [](const detect::MarkerDetector& d) { return d.family().Spec(); })
      .def(
          "detect",
          [](const detect::MarkerDetector& detector, const py::array& image) {
            const cv::Mat gray = GrayView(image);
            detect::Detections found;
            {
              py::gil_scoped_release release;
              found = detector.Detect(gray);
            }
            return DetectionsTuple(found);
          },
          py::arg("image"),
          "(ids (N,) int32, corners (N, 4, 2) float64) of the markers in a 2-D uint8 image; "
          "corners in OpenCV's convention and order, sorted by id.");
}

}  // namespace calibproj::bindings
