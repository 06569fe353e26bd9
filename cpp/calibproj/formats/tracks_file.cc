#include "calibproj/formats/tracks_file.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "calibproj/formats/files.h"

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
      throw std::invalid_argument("camera '" + tracks.cameras[camera[i]] + "' observes point " +
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

Tracks ReadTracks(const fs::path& path) {
  const nlohmann::json document = ReadSchemaJson(path, "tracks", 1);
  try {
    const auto& names_json = document.at("cameras");
    const auto& observations = document.at("observations");
    if (!names_json.is_array()) throw std::invalid_argument("cameras: expected a list of names");
    if (!observations.is_object()) throw std::invalid_argument("observations: expected an object {camera: {point_ids, xy}}");
    if (document.contains("undistorted") && !BoolValue(document.at("undistorted"), "undistorted")) {
      throw std::invalid_argument("only undistorted observations are supported");
    }
    std::vector<std::string> names;
    for (const auto& name : names_json) names.push_back(StringValue(name, "cameras"));
    // Observations are keyed by name: a second camera of one name would get the first's.
    std::vector<std::string> sorted = names;
    std::sort(sorted.begin(), sorted.end());
    if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end()) {
      std::string listed;
      for (const auto& name : names) listed += (listed.empty() ? "'" : ", '") + name + "'";
      throw std::invalid_argument("duplicate camera names in [" + listed + "]");
    }
    std::vector<int> camera;
    std::vector<std::int64_t> ids;
    std::vector<Eigen::Vector2d> pixels;
    for (const auto& [name, entry] : observations.items()) {
      if (std::find(names.begin(), names.end(), name) == names.end()) {
        throw std::invalid_argument("observations of camera(s) ['" + name + "'] not listed in cameras");
      }
    }
    for (size_t c = 0; c < names.size(); ++c) {
      if (!observations.contains(names[c])) continue;
      const auto& entry = observations.at(names[c]);
      const std::string where = "observations." + names[c];
      const auto& ids_json = entry.at("point_ids");
      const auto& xy_json = entry.at("xy");
      if (!ids_json.is_array() || !xy_json.is_array()) {
        throw std::invalid_argument(where + ": point_ids and xy must be lists");
      }
      if (ids_json.size() != xy_json.size()) {
        throw std::invalid_argument(where + ": " + std::to_string(ids_json.size()) + " point_ids but " +
                                    std::to_string(xy_json.size()) + " xy");
      }
      for (size_t k = 0; k < ids_json.size(); ++k) {
        const std::vector<double> xy = NumberList(xy_json[k], where + ".xy");
        if (xy.size() != 2) throw std::invalid_argument("observations must be finite pixel pairs");
        const long long id = IntegerValue(ids_json[k], where + ".point_ids", std::numeric_limits<std::int64_t>::min(),
                                          std::numeric_limits<std::int64_t>::max());
        if (id < 0) throw std::invalid_argument("point ids must be non-negative");
        camera.push_back(static_cast<int>(c));
        ids.push_back(id);
        pixels.emplace_back(xy[0], xy[1]);
      }
    }
    std::optional<int> markers;
    if (document.contains("markers_per_array") && !document.at("markers_per_array").is_null()) {
      markers = static_cast<int>(IntegerValue(document.at("markers_per_array"), "markers_per_array", 1,
                                              std::numeric_limits<int>::max()));
    }
    return MakeTracks(names, camera, ids, pixels, markers);
  } catch (const nlohmann::json::exception& error) {
    throw InputError(path.string() + ": " + error.what());
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
