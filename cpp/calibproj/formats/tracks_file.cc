#include "calibproj/formats/tracks_file.h"

#include <algorithm>
#include <iterator>
#include <cmath>
#include <limits>
#include <numeric>

#include "calibproj/formats/files.h"
#include "calibproj/formats/json_values.h"

namespace calibproj::formats {

namespace fs = std::filesystem;

Tracks MakeTracks(std::vector<std::string> cameras, const std::vector<int>& camera,
                  const std::vector<std::int64_t>& ids, const std::vector<Eigen::Vector2d>& xy,
                  std::optional<int> markers_per_array) {
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

Tracks Tracks::WithoutCameras(const std::vector<std::string>& names) const {
  std::vector<std::string> kept;
  std::vector<int> remap(cameras.size(), -1);
  for (size_t c = 0; c < cameras.size(); ++c) {
    if (std::find(names.begin(), names.end(), cameras[c]) == names.end()) {
      remap[c] = static_cast<int>(kept.size());
      kept.push_back(cameras[c]);
    }
  }
  std::vector<int> camera;
  std::vector<std::int64_t> ids;
  std::vector<Eigen::Vector2d> pixels;
  for (int i = 0; i < camera_index.size(); ++i) {
    if (remap[camera_index(i)] < 0) continue;
    camera.push_back(remap[camera_index(i)]);
    ids.push_back(point_ids[point_index(i)]);
    pixels.push_back(xy.row(i).transpose());
  }
  return MakeTracks(kept, camera, ids, pixels, markers_per_array);
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
    for (int i = 0; i < part->camera_index.size(); ++i) {
      const auto& name = part->cameras[part->camera_index(i)];
      camera.push_back(static_cast<int>(std::find(cameras.begin(), cameras.end(), name) - cameras.begin()));
      ids.push_back(part->point_ids[part->point_index(i)]);
      pixels.push_back(part->xy.row(i).transpose());
    }
  }
  return MakeTracks(cameras, camera, ids, pixels, first.markers_per_array);
}

namespace {

constexpr std::int64_t kMaxPointId = std::numeric_limits<std::int64_t>::max();
constexpr long long kMaxMarkersPerArray = std::numeric_limits<std::int32_t>::max();

// One camera's point ids and pixels (none when the camera has no entry).
void CameraObservations(const nlohmann::json& observations, const std::string& name, int camera,
                        std::vector<int>* cameras, std::vector<std::int64_t>* ids,
                        std::vector<Eigen::Vector2d>* pixels) {
  const auto entry = observations.find(name);
  if (entry == observations.end() || entry->is_null()) return;
  const std::string where = "observations." + name;
  if (!entry->is_object() || !entry->contains("point_ids") || !entry->contains("xy")) {
    throw std::invalid_argument(where + ": expected an object {point_ids, xy}");
  }
  const std::vector<std::int64_t> camera_ids = IntegerListOf(entry->at("point_ids"), where + ".point_ids", 0, kMaxPointId);
  const NumberArray xy = NumberArrayOf(entry->at("xy"), where + ".xy", 2);
  if (camera_ids.size() != xy.shape[0]) {
    throw std::invalid_argument(where + ": " + std::to_string(camera_ids.size()) + " point_ids but " +
                                std::to_string(xy.shape[0]) + " xy");
  }
  for (size_t k = 0; k < camera_ids.size(); ++k) {
    cameras->push_back(camera);
    ids->push_back(camera_ids[k]);
    pixels->emplace_back(xy.values[2 * k], xy.values[2 * k + 1]);
  }
}

std::optional<int> MarkersPerArray(const nlohmann::json& document) {
  const auto value = document.find("markers_per_array");
  if (value == document.end() || value->is_null()) return std::nullopt;
  const bool integer = value->is_number_integer() || value->is_number_unsigned();
  if (!integer || !(value->get<double>() > 0 && value->get<double>() <= kMaxMarkersPerArray)) {
    throw std::invalid_argument("markers_per_array must be a positive integer or null, got " + Describe(*value));
  }
  return value->get<int>();
}

Tracks TracksFromDocument(const nlohmann::json& document) {
  const auto names_json = document.find("cameras");
  const auto observations = document.find("observations");
  std::vector<std::string> names;
  if (names_json == document.end() || !names_json->is_array()) throw std::invalid_argument("cameras: expected a list of names");
  for (const auto& name : *names_json) {
    if (!name.is_string()) throw std::invalid_argument("cameras: expected a list of names");
    names.push_back(name.get<std::string>());
  }
  if (observations == document.end() || !observations->is_object()) {
    throw std::invalid_argument("observations: expected an object {camera: {point_ids, xy}}");
  }
  std::vector<std::string> unknown;
  for (const auto& [name, entry] : observations->items()) {
    if (std::find(names.begin(), names.end(), name) == names.end()) unknown.push_back(name);
  }
  std::sort(unknown.begin(), unknown.end());
  if (!unknown.empty()) {
    throw std::invalid_argument("observations of camera(s) " + PythonList(unknown) + " not listed in cameras");
  }
  const auto undistorted = document.find("undistorted");
  if (undistorted != document.end() && !BoolValue(*undistorted, "undistorted")) {
    throw std::invalid_argument("only undistorted observations are supported");
  }
  std::vector<int> cameras;
  std::vector<std::int64_t> ids;
  std::vector<Eigen::Vector2d> pixels;
  for (size_t c = 0; c < names.size(); ++c) {
    CameraObservations(*observations, names[c], static_cast<int>(c), &cameras, &ids, &pixels);
  }
  // Observations are keyed by name: a second camera of one name would get the first's.
  std::vector<std::string> sorted = names;
  std::sort(sorted.begin(), sorted.end());
  if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end()) {
    throw std::invalid_argument("duplicate camera names in " + PythonList(names));
  }
  Tracks tracks = MakeTracks(names, cameras, ids, pixels, std::nullopt);
  tracks.markers_per_array = MarkersPerArray(document);
  return tracks;
}

}  // namespace

Tracks ReadTracks(const fs::path& path) {
  const nlohmann::json document = ReadSchemaJson(path, "tracks", 1);
  try {
    return TracksFromDocument(document);
  } catch (const std::invalid_argument& error) {
    throw InputError(path.string() + ": " + error.what());
  }
}

namespace {

// Compact JSON with non-ASCII escaped, as Python's json.dumps writes it.
std::string CompactJson(const nlohmann::json& value) { return value.dump(-1, ' ', true); }

std::string CameraBlock(const Tracks& tracks, int camera) {
  // The numbers as Python writes them: nlohmann's dtoa does not always give the
  // shortest digits, and both commands must write the same bytes.
  nlohmann::json ids = nlohmann::json::array();
  std::string xy;
  for (int i = 0; i < tracks.camera_index.size(); ++i) {
    if (tracks.camera_index(i) != camera) continue;
    ids.push_back(tracks.point_ids[tracks.point_index(i)]);
    xy += (xy.empty() ? "[" : ",[") + PythonFloat(tracks.xy(i, 0)) + "," + PythonFloat(tracks.xy(i, 1)) + "]";
  }
  return "  " + CompactJson(tracks.cameras[camera]) + ": {\n   \"point_ids\": " + CompactJson(ids) +
         ",\n   \"xy\": [" + xy + "]\n  }";
}

}  // namespace

void WriteTracks(const fs::path& path, const Tracks& tracks) {
  try {
    tracks.Check();
  } catch (const std::invalid_argument& error) {
    throw std::invalid_argument(path.string() + ": cannot write " + error.what());
  }
  nlohmann::ordered_json header;
  header["markers_per_array"] = tracks.markers_per_array ? nlohmann::json(*tracks.markers_per_array) : nullptr;
  header["undistorted"] = true;
  header["cameras"] = tracks.cameras;
  std::string text = DumpSchemaJson("tracks", 1, header);
  text.resize(text.size() - 3);  // drop the closing "\n}\n" but keep the last entry
  text += ",\n \"observations\": {\n";
  for (size_t c = 0; c < tracks.cameras.size(); ++c) {
    text += (c ? ",\n" : "") + CameraBlock(tracks, static_cast<int>(c));
  }
  text += "\n }\n}\n";
  AtomicWrite(path, text);
}

}  // namespace calibproj::formats
