#include "calibproj/formats/tracks_file.h"

#include <algorithm>
#include <limits>

#include "calibproj/formats/files.h"
#include "calibproj/formats/json_values.h"

namespace calibproj::formats {

namespace fs = std::filesystem;

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
  // Observations are keyed by name: MakeTracks refuses a second camera of one name.
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
