#include "calibproj/formats/tracks.h"

#include <algorithm>
#include <iterator>
#include <numeric>
#include <stdexcept>

#include "calibproj/formats/files.h"
#include "calibproj/formats/json_values.h"

namespace calibproj::formats {

namespace {

void CheckCameraNames(const std::vector<std::string>& cameras) {
  std::vector<std::string> sorted = cameras;
  std::sort(sorted.begin(), sorted.end());
  if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end()) {
    throw std::invalid_argument("duplicate camera names in " + PythonList(cameras));
  }
}

void CheckObservation(const std::vector<std::string>& cameras, int camera, std::int64_t id, const Eigen::Vector2d& xy) {
  if (camera < 0 || camera >= static_cast<int>(cameras.size())) {
    throw std::invalid_argument("camera index out of range [0, " + std::to_string(cameras.size()) + ")");
  }
  if (id < 0) throw std::invalid_argument("point ids must be non-negative");
  if (!xy.allFinite()) throw std::invalid_argument("observations must be finite");
}

// std::invalid_argument "`what` unknown camera(s) [...]" (sorted, each once) when a
// name is not among `cameras`.
void CheckKnown(const std::vector<std::string>& cameras, const std::vector<std::string>& names,
                const std::string& what = "") {
  std::vector<std::string> unknown;
  for (const auto& name : names) {
    if (std::find(cameras.begin(), cameras.end(), name) == cameras.end()) unknown.push_back(name);
  }
  std::sort(unknown.begin(), unknown.end());
  unknown.erase(std::unique(unknown.begin(), unknown.end()), unknown.end());
  if (!unknown.empty()) throw std::invalid_argument(what + "unknown camera(s) " + PythonList(unknown));
}

}  // namespace

std::vector<int> CameraIndices(const std::vector<std::string>& cameras, const std::vector<std::int64_t>& index) {
  std::vector<int> out;
  for (const std::int64_t camera : index) {
    if (camera < 0 || camera >= static_cast<std::int64_t>(cameras.size())) {
      throw std::invalid_argument("camera index out of range [0, " + std::to_string(cameras.size()) + ")");
    }
    out.push_back(static_cast<int>(camera));
  }
  return out;
}

std::vector<int> CameraIndices(const std::vector<std::string>& cameras, const std::vector<std::string>& names) {
  CheckKnown(cameras, names, "observations of ");
  std::vector<int> out;
  for (const auto& name : names) {
    out.push_back(static_cast<int>(std::find(cameras.begin(), cameras.end(), name) - cameras.begin()));
  }
  return out;
}

Tracks MakeTracks(std::vector<std::string> cameras, const std::vector<int>& camera,
                  const std::vector<std::int64_t>& ids, const std::vector<Eigen::Vector2d>& xy,
                  std::optional<int> markers_per_array) {
  CheckCameraNames(cameras);
  if (camera.size() != ids.size() || ids.size() != xy.size()) {
    throw std::invalid_argument("observation arrays differ in length: " + std::to_string(camera.size()) +
                                " cameras, " + std::to_string(ids.size()) + " ids, " + std::to_string(xy.size()) +
                                " xy");
  }
  if (markers_per_array && *markers_per_array <= 0) {
    throw std::invalid_argument("markers_per_array must be a positive integer or null, got " +
                                std::to_string(*markers_per_array));
  }
  for (size_t i = 0; i < ids.size(); ++i) CheckObservation(cameras, camera[i], ids[i], xy[i]);
  std::vector<size_t> order(ids.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return std::tie(camera[a], ids[a]) < std::tie(camera[b], ids[b]);
  });
  Tracks tracks;
  tracks.cameras = std::move(cameras);
  tracks.markers_per_array = markers_per_array;
  tracks.point_ids = ids;
  std::sort(tracks.point_ids.begin(), tracks.point_ids.end());
  tracks.point_ids.erase(std::unique(tracks.point_ids.begin(), tracks.point_ids.end()), tracks.point_ids.end());
  const int n = static_cast<int>(order.size());
  tracks.camera_index.resize(n);
  tracks.point_index.resize(n);
  tracks.xy.resize(n, 2);
  for (int k = 0; k < n; ++k) {
    const size_t i = order[k];
    if (k > 0 && camera[i] == camera[order[k - 1]] && ids[i] == ids[order[k - 1]]) {
      throw std::invalid_argument("camera " + PythonRepr(tracks.cameras[camera[i]]) + " observes point " +
                                  std::to_string(ids[i]) + " twice");
    }
    tracks.camera_index(k) = camera[i];
    tracks.point_index(k) = static_cast<int>(
        std::lower_bound(tracks.point_ids.begin(), tracks.point_ids.end(), ids[i]) - tracks.point_ids.begin());
    tracks.xy.row(k) = xy[i].transpose();
  }
  return tracks;
}

void Tracks::Check() const {
  const Eigen::Index count = camera_index.size();
  if (point_index.size() != count || xy.rows() != count) {
    throw std::invalid_argument("tracks: camera_index, point_index and xy differ in length");
  }
  for (Eigen::Index i = 0; i < count; ++i) {
    if (camera_index[i] < 0 || camera_index[i] >= static_cast<int>(cameras.size()) || point_index[i] < 0 ||
        point_index[i] >= static_cast<int>(point_ids.size())) {
      throw std::invalid_argument("tracks: observation " + std::to_string(i) + " has no camera or point");
    }
    // JSON has no NaN or infinity: such a pixel would make a file no reader takes.
    if (!xy.row(i).allFinite()) {
      throw std::invalid_argument("tracks: observation " + std::to_string(i) + " (camera '" +
                                  cameras[camera_index[i]] + "') is not finite");
    }
  }
}

int Tracks::CameraPosition(const std::string& name) const {
  const auto found = std::find(cameras.begin(), cameras.end(), name);
  if (found == cameras.end()) {
    std::string list;
    for (const auto& camera : cameras) list += (list.empty() ? "" : ", ") + camera;
    throw std::invalid_argument("no camera " + PythonRepr(name) + " in tracks (cameras: " + list + ")");
  }
  return static_cast<int>(found - cameras.begin());
}

std::vector<int> Tracks::CountsPerCamera() const {
  std::vector<int> counts(cameras.size(), 0);
  for (int i = 0; i < NumObservations(); ++i) ++counts[camera_index(i)];
  return counts;
}

std::vector<int> Tracks::TrackLengths() const {
  std::vector<int> lengths(point_ids.size(), 0);
  for (int i = 0; i < NumObservations(); ++i) ++lengths[point_index(i)];
  return lengths;
}

Eigen::Matrix<bool, Eigen::Dynamic, Eigen::Dynamic> Tracks::Visibility() const {
  Eigen::Matrix<bool, Eigen::Dynamic, Eigen::Dynamic> seen =
      Eigen::Matrix<bool, Eigen::Dynamic, Eigen::Dynamic>::Constant(point_ids.size(), cameras.size(), false);
  for (int i = 0; i < NumObservations(); ++i) seen(point_index(i), camera_index(i)) = true;
  return seen;
}

Eigen::MatrixXi Tracks::PairCounts() const {
  const Eigen::MatrixXi seen = Visibility().cast<int>();
  return seen.transpose() * seen;
}

std::map<std::pair<std::string, std::string>, int> Tracks::PairCountsByName() const {
  const Eigen::MatrixXi counts = PairCounts();
  std::map<std::pair<std::string, std::string>, int> pairs;
  for (size_t a = 0; a < cameras.size(); ++a) {
    for (size_t b = a + 1; b < cameras.size(); ++b) pairs[{cameras[a], cameras[b]}] = counts(a, b);
  }
  return pairs;
}

std::pair<std::vector<std::int64_t>, ba::PixelMatrix> Tracks::ObservationsOf(const std::string& camera) const {
  const int position = CameraPosition(camera);
  std::vector<std::int64_t> ids;
  std::vector<int> rows;
  for (int i = 0; i < NumObservations(); ++i) {
    if (camera_index(i) != position) continue;
    ids.push_back(point_ids[point_index(i)]);
    rows.push_back(i);
  }
  ba::PixelMatrix pixels(rows.size(), 2);
  for (size_t k = 0; k < rows.size(); ++k) pixels.row(k) = xy.row(rows[k]);
  return {ids, pixels};
}

Tracks Tracks::WithPixels(const ba::PixelMatrix& pixels) const {
  if (pixels.rows() != NumObservations()) {
    throw std::invalid_argument("xy: " + std::to_string(pixels.rows()) + " pixels for " +
                                std::to_string(NumObservations()) + " observations");
  }
  if (!pixels.allFinite()) throw std::invalid_argument("observations must be finite");
  Tracks moved = *this;
  moved.xy = pixels;
  return moved;
}

Tracks Tracks::Select(const std::vector<bool>& keep, const std::vector<std::string>* names) const {
  if (static_cast<int>(keep.size()) != NumObservations()) {
    throw std::invalid_argument("the mask has " + std::to_string(keep.size()) + " entries for " +
                                std::to_string(NumObservations()) + " observations");
  }
  const std::vector<std::string>& kept = names ? *names : cameras;
  std::vector<int> remap(cameras.size(), -1);
  for (size_t c = 0; c < cameras.size(); ++c) {
    const auto found = std::find(kept.begin(), kept.end(), cameras[c]);
    if (found != kept.end()) remap[c] = static_cast<int>(found - kept.begin());
  }
  std::vector<int> camera;
  std::vector<std::int64_t> ids;
  std::vector<Eigen::Vector2d> pixels;
  for (int i = 0; i < NumObservations(); ++i) {
    if (!keep[i] || remap[camera_index(i)] < 0) continue;
    camera.push_back(remap[camera_index(i)]);
    ids.push_back(point_ids[point_index(i)]);
    pixels.push_back(xy.row(i).transpose());
  }
  return MakeTracks(kept, camera, ids, pixels, markers_per_array);
}

Tracks Tracks::WithoutCameras(const std::vector<std::string>& names) const {
  CheckKnown(cameras, names);
  std::vector<std::string> kept;
  std::copy_if(cameras.begin(), cameras.end(), std::back_inserter(kept),
               [&](const std::string& name) { return std::find(names.begin(), names.end(), name) == names.end(); });
  return Select(std::vector<bool>(NumObservations(), true), &kept);
}

Tracks Tracks::OnlyCameras(const std::vector<std::string>& names) const {
  CheckKnown(cameras, names);
  return Select(std::vector<bool>(NumObservations(), true), &names);
}

Tracks Tracks::WithoutPoints(const std::vector<std::int64_t>& ids) const {
  std::vector<std::int64_t> dropped = ids;
  std::sort(dropped.begin(), dropped.end());
  std::vector<bool> keep(NumObservations());
  for (int i = 0; i < NumObservations(); ++i) {
    keep[i] = !std::binary_search(dropped.begin(), dropped.end(), point_ids[point_index(i)]);
  }
  return Select(keep);
}

Tracks Tracks::WithMinTrackLength(int min_cameras) const {
  const std::vector<int> lengths = TrackLengths();
  std::vector<bool> keep(NumObservations());
  for (int i = 0; i < NumObservations(); ++i) keep[i] = lengths[point_index(i)] >= min_cameras;
  return Select(keep);
}

Tracks MergeTracks(const Tracks& first, const Tracks& second) {
  if (first.markers_per_array != second.markers_per_array) {
    const auto text = [](const std::optional<int>& value) { return value ? std::to_string(*value) : "none"; };
    throw std::invalid_argument("the tracks have " + text(first.markers_per_array) + " and " +
                                text(second.markers_per_array) + " markers per array: not of one sequence");
  }
  std::vector<std::int64_t> shared;
  std::set_intersection(first.point_ids.begin(), first.point_ids.end(), second.point_ids.begin(),
                        second.point_ids.end(), std::back_inserter(shared));
  if (!shared.empty()) {
    throw std::invalid_argument(std::to_string(shared.size()) + " point id(s) in both, e.g. " +
                                std::to_string(shared.front()) +
                                ": the second projection must show only arrays the first did not (calibproj generate "
                                "--densify)");
  }
  std::vector<std::string> cameras = first.cameras;
  for (const auto& name : second.cameras) {
    if (std::find(cameras.begin(), cameras.end(), name) == cameras.end()) cameras.push_back(name);
  }
  std::vector<int> camera;
  std::vector<std::int64_t> ids;
  std::vector<Eigen::Vector2d> pixels;
  for (const Tracks* part : {&first, &second}) {
    for (int i = 0; i < part->NumObservations(); ++i) {
      const auto& name = part->cameras[part->camera_index(i)];
      camera.push_back(static_cast<int>(std::find(cameras.begin(), cameras.end(), name) - cameras.begin()));
      ids.push_back(part->point_ids[part->point_index(i)]);
      pixels.push_back(part->xy.row(i).transpose());
    }
  }
  return MakeTracks(cameras, camera, ids, pixels, first.markers_per_array);
}

}  // namespace calibproj::formats
