// calibproj._core.formats.Tracks: the core's tracks as the package's one Tracks class
// (calibproj.formats.tracks.Tracks), its arrays read-only numpy views of the core's memory.

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cstdint>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "calibproj/formats/tracks_file.h"
#include "arrays.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

using formats::Tracks;
using IdArray = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>;
using PixelArray = py::array_t<double, py::array::c_style | py::array::forcecast>;
using BoolArray = py::array_t<bool, py::array::c_style | py::array::forcecast>;

std::vector<std::int64_t> Flat(const IdArray& ids) {
  return std::vector<std::int64_t>(ids.data(), ids.data() + ids.size());
}

// Pixels (x, y) of any shape, read row by row.
ba::PixelMatrix PixelRows(const PixelArray& xy) {
  if (xy.size() % 2 != 0) {
    throw std::invalid_argument("xy: expected pixels (x, y), got " + std::to_string(xy.size()) + " numbers");
  }
  return Eigen::Map<const ba::PixelMatrix>(xy.data(), xy.size() / 2, 2);
}

std::vector<Eigen::Vector2d> Pixels(const PixelArray& xy) {
  const ba::PixelMatrix rows = PixelRows(xy);
  std::vector<Eigen::Vector2d> out(rows.rows());
  for (Eigen::Index i = 0; i < rows.rows(); ++i) out[i] = rows.row(i).transpose();
  return out;
}

std::optional<int> MarkersPerArray(const std::optional<std::int64_t>& value) {
  if (value && !(*value > 0 && *value <= std::numeric_limits<std::int32_t>::max())) {
    throw std::invalid_argument("markers_per_array must be a positive integer or null, got " + std::to_string(*value));
  }
  return value ? std::optional<int>(static_cast<int>(*value)) : std::nullopt;
}

Tracks FromObservations(const std::vector<std::string>& camera_names,
                        const std::variant<std::vector<std::string>, IdArray>& cameras, const IdArray& point_ids,
                        const PixelArray& xy, const std::optional<std::int64_t>& markers_per_array) {
  const std::vector<int> index =
      std::holds_alternative<IdArray>(cameras)
          ? formats::CameraIndices(camera_names, Flat(std::get<IdArray>(cameras)))
          : formats::CameraIndices(camera_names, std::get<std::vector<std::string>>(cameras));
  return formats::MakeTracks(camera_names, index, Flat(point_ids), Pixels(xy), MarkersPerArray(markers_per_array));
}

std::vector<bool> Mask(const BoolArray& mask) { return std::vector<bool>(mask.data(), mask.data() + mask.size()); }

py::array CountsArray(const std::vector<int>& counts) {
  return py::array_t<std::int64_t>(counts.size(), std::vector<std::int64_t>(counts.begin(), counts.end()).data());
}

// The arrays of the Tracks `self`, without copies.
py::array PointIdsView(const py::object& self) {
  const auto& t = self.cast<const Tracks&>();
  return ReadOnlyView(t.point_ids.data(), {static_cast<py::ssize_t>(t.point_ids.size())}, self);
}

py::array CameraIndexView(const py::object& self) {
  const auto& t = self.cast<const Tracks&>();
  return ReadOnlyView(t.camera_index.data(), {t.camera_index.size()}, self);
}

py::array PointIndexView(const py::object& self) {
  const auto& t = self.cast<const Tracks&>();
  return ReadOnlyView(t.point_index.data(), {t.point_index.size()}, self);
}

py::array PixelsView(const py::object& self) {
  const auto& t = self.cast<const Tracks&>();
  return ReadOnlyView(t.xy.data(), {t.xy.rows(), py::ssize_t{2}}, self);
}

}  // namespace

void register_tracks(py::module_& m) {
  py::class_<Tracks>(m, "Tracks", R"(Observations of points by cameras: calibproj.formats.tracks.Tracks.

A point is one projected MSM, identified by (array, marker) with point id
array * markers_per_array + marker, or, for evaluation data, any non-negative integer
(markers_per_array then None). Observations are stored flat, one row per (camera,
point), ordered by camera then point id: camera_index into camera_names, point_index
into point_ids, and xy, the undistorted pixels. Build with Tracks.from_observations
or Tracks.read; the arrays are read-only.)")
      .def_static("from_observations", &FromObservations, py::arg("camera_names"), py::arg("cameras"),
                  py::arg("point_ids"), py::arg("xy"), py::arg("markers_per_array") = py::none(),
                  "Tracks from one row per observation: per observation the camera (its index into camera_names, "
                  "or its name), the point id and the undistorted pixel (N, 2); sorted, points indexed. ValueError "
                  "for duplicate camera names, an unknown camera, a negative id, a pixel not finite or a point seen "
                  "twice by one camera.")
      .def_static(
          "empty",
          [](const std::vector<std::string>& camera_names, const std::optional<std::int64_t>& markers_per_array) {
            return formats::MakeTracks(camera_names, {}, {}, {}, MarkersPerArray(markers_per_array));
          },
          py::arg("camera_names"), py::arg("markers_per_array") = py::none(), "Tracks without observations")
      .def_static("read", &formats::ReadTracks, py::arg("path"),
                  "Reads tracks.json; InputError naming the file and the problem")
      .def("write", [](const Tracks& t, const std::filesystem::path& path) { formats::WriteTracks(path, t); },
           py::arg("path"), "Writes tracks.json atomically, each camera's arrays on one line each")
      .def_property_readonly("camera_names", [](const Tracks& t) { return py::tuple(py::cast(t.cameras)); },
                             "every camera, in order, even one that saw nothing")
      .def_property_readonly("point_ids", &PointIdsView, "(P,) int64, sorted, unique")
      .def_property_readonly("camera_index", &CameraIndexView, "(M,) int32 into camera_names")
      .def_property_readonly("point_index", &PointIndexView, "(M,) int32 into point_ids")
      .def_property_readonly("xy", &PixelsView, "(M, 2) float64 undistorted pixels")
      .def_readonly("markers_per_array", &Tracks::markers_per_array,
                    "markers per MSM array when ids are (array, marker) keys, else None")
      .def("__len__", &Tracks::NumObservations, "Number of observations")
      .def_property_readonly("num_cameras", [](const Tracks& t) { return t.cameras.size(); })
      .def_property_readonly("num_points", [](const Tracks& t) { return t.point_ids.size(); })
      .def_property_readonly(
          "keys",
          [](const Tracks& t) {
            if (!t.markers_per_array) {
              throw std::invalid_argument("these tracks use generic point ids, not (array, marker) keys");
            }
            py::array_t<std::int64_t> keys({static_cast<py::ssize_t>(t.point_ids.size()), py::ssize_t{2}});
            auto out = keys.mutable_unchecked<2>();
            for (size_t p = 0; p < t.point_ids.size(); ++p) {
              out(p, 0) = t.point_ids[p] / *t.markers_per_array;
              out(p, 1) = t.point_ids[p] % *t.markers_per_array;
            }
            return keys;
          },
          "(array, marker) of every point, (P, 2); ValueError for generic point ids")
      .def(
          "observation_ids",
          [](const Tracks& t) {
            py::array_t<std::int64_t> ids(t.NumObservations());
            for (int i = 0; i < t.NumObservations(); ++i) ids.mutable_at(i) = t.point_ids[t.point_index(i)];
            return ids;
          },
          "Point id of every observation, (M,)")
      .def(
          "counts_per_camera",
          [](const Tracks& t) {
            const std::vector<int> counts = t.CountsPerCamera();
            std::map<std::string, int> named;
            for (size_t c = 0; c < counts.size(); ++c) named[t.cameras[c]] = counts[c];
            return named;
          },
          "{camera: observations}")
      .def("track_lengths", [](const Tracks& t) { return CountsArray(t.TrackLengths()); },
           "Number of cameras that saw each point, (P,)")
      .def("visibility", &Tracks::Visibility, "Boolean (P, C): point p seen by camera c")
      .def("pair_counts", &Tracks::PairCounts,
           "Points shared by every pair of cameras, (C, C); the diagonal is per-camera counts")
      .def("pair_counts_by_name", &Tracks::PairCountsByName,
           "Shared points of every camera pair (a, b) with a before b, zeros included")
      .def(
          "observations",
          [](const Tracks& t, const std::string& camera) {
            auto [ids, pixels] = t.ObservationsOf(camera);
            return py::make_tuple(py::array_t<std::int64_t>(ids.size(), ids.data()), pixels);
          },
          py::arg("camera"), "Point ids and undistorted pixels seen by one camera; ValueError for an unknown camera")
      .def(
          "bundle_arrays",
          [](const py::object& self) {
            return py::make_tuple(CameraIndexView(self), PointIndexView(self), PixelsView(self));
          },
          "(camera_index int32 (M,), point_index int32 (M,), xy float64 (M, 2))")
      .def(
          "select",
          [](const Tracks& t, const BoolArray& mask, const std::optional<std::vector<std::string>>& camera_names) {
            return t.Select(Mask(mask), camera_names ? &*camera_names : nullptr);
          },
          py::arg("observation_mask"), py::arg("camera_names") = py::none(),
          "The observations where the mask is true, of the cameras camera_names (in that order; all when None)")
      .def(
          "with_xy",
          [](const Tracks& t, const PixelArray& xy) { return t.WithPixels(PixelRows(xy)); },
          py::arg("xy"), "The same observations at other undistorted pixels, (M, 2) in the same order")
      .def("drop_cameras", &Tracks::WithoutCameras, py::arg("names"),
           "Without the named cameras and their observations; ValueError naming unknown ones")
      .def("keep_cameras", &Tracks::OnlyCameras, py::arg("names"),
           "Only the named cameras, in the given order; ValueError naming unknown ones")
      .def("drop_points", &Tracks::WithoutPoints, py::arg("point_ids"), "Without the observations of these points")
      .def("with_min_track_length", &Tracks::WithMinTrackLength, py::arg("min_cameras") = 2,
           "Only the points seen by at least min_cameras cameras")
      .def(py::pickle(
          [](const Tracks& t) {
            return py::make_tuple(t.cameras, t.point_ids, t.camera_index, t.point_index, t.xy, t.markers_per_array);
          },
          [](const py::tuple& state) {
            if (state.size() != 6) throw std::invalid_argument("Tracks: not a pickled Tracks");
            Tracks t{state[0].cast<std::vector<std::string>>(), state[1].cast<std::vector<std::int64_t>>(),
                     state[2].cast<Eigen::VectorXi>(), state[3].cast<Eigen::VectorXi>(),
                     state[4].cast<ba::PixelMatrix>(), state[5].cast<std::optional<int>>()};
            t.Check();
            return t;
          }))
      .def("__repr__", [](const Tracks& t) {
        return "Tracks(" + std::to_string(t.cameras.size()) + " cameras, " + std::to_string(t.point_ids.size()) +
               " points, " + std::to_string(t.NumObservations()) + " observations)";
      });
}

}  // namespace calibproj::bindings
