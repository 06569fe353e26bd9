// Reading a results folder's camera_poses.json, metrics.json and points.ply back into a
// Calibration, with the checks (and the messages) of the Python package's readers.

#include <Eigen/Dense>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>

#include "calibproj/formats/calibration.h"
#include "calibproj/formats/files.h"
#include "calibproj/formats/json_values.h"

namespace calibproj::formats {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr double kRotationTolerance = 1e-6;  // calibproj.io.poses.ROTATION_TOLERANCE
const std::set<std::string> kUnits = {"arbitrary", "m"};
const std::set<std::string> kModels = {"free", "coplanar"};

double NonNegative(const json& value, const std::string& where) {
  const double number = NumberValue(value, where);
  if (number < 0.0) throw std::invalid_argument(where + ": must be at least 0, got " + Describe(value));
  return number;
}

std::optional<double> OptionalNonNegative(const json& entry, const std::string& key, const std::string& where) {
  const auto found = entry.find(key);
  if (found == entry.end() || found->is_null()) return std::nullopt;
  return NonNegative(*found, where + "." + key);
}

Eigen::Matrix3d RotationOf(const json& value, const std::string& where) {
  const NumberArray R = NumbersOf(value, where);
  if (R.shape != std::vector<size_t>{3, 3}) throw std::invalid_argument(where + ": expected 3x3 numbers");
  return Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(R.values.data());
}

Eigen::Vector3d VectorOf(const json& value, const std::string& where) {
  const NumberArray v = NumbersOf(value, where);
  if (v.shape != std::vector<size_t>{3}) throw std::invalid_argument(where + ": expected 3 numbers");
  return Eigen::Map<const Eigen::Vector3d>(v.values.data());
}

// The keys of the document's object `member` in the file's order (nlohmann::json sorts
// them; the cameras keep the order they were written in, as Python's reader keeps it).
std::vector<std::string> KeysInFileOrder(const fs::path& path, const std::string& member) {
  std::ifstream in(path, std::ios::binary);
  const nlohmann::ordered_json document = nlohmann::ordered_json::parse(in, nullptr, false);
  std::vector<std::string> keys;
  if (!document.is_object() || !document.contains(member) || !document[member].is_object()) return keys;
  for (const auto& item : document[member].items()) keys.push_back(item.key());
  return keys;
}

const json& Member(const json& object, const std::string& key, const std::string& expected) {
  const auto found = object.find(key);
  if (found == object.end() || !found->is_object()) throw std::invalid_argument(key + ": expected " + expected);
  return *found;
}

CameraPose PoseOf(const std::string& name, const json& entry) {
  const std::string where = "cameras." + name;
  if (!entry.is_object() || !entry.contains("R") || !entry.contains("t")) {
    throw std::invalid_argument(where + ": expected an object with R (3x3) and t (3)");
  }
  CameraPose pose{name, RotationOf(entry["R"], where + ".R"), VectorOf(entry["t"], where + ".t")};
  if (entry.contains("center")) VectorOf(entry["center"], where + ".center");
  if (entry.contains("weak")) BoolValue(entry["weak"], where + ".weak");
  OptionalNonNegative(entry, "rotation_sigma_deg", where);
  OptionalNonNegative(entry, "centre_sigma", where);
  const double off = (pose.R * pose.R.transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (!(off <= kRotationTolerance) || pose.R.determinant() < 0.0) {
    throw std::invalid_argument(where + ": R is not a rotation matrix");
  }
  return pose;
}

void ReadPoses(const fs::path& path, Calibration* calibration) {
  const json document = ReadSchemaJson(path, "camera_poses", 1);
  try {
    const auto unit = document.find("unit");
    if (unit == document.end() || !unit->is_string() || !kUnits.count(unit->get<std::string>())) {
      throw std::invalid_argument("unit must be one of ['arbitrary', 'm'], got " +
                                  (unit == document.end() ? std::string("null") : Describe(*unit)));
    }
    calibration->unit = unit->get<std::string>();
    const auto frame = document.find("frame");
    if (frame != document.end() && *frame != "floor") {
      throw std::invalid_argument("frame must be 'floor', got " + Describe(*frame));
    }
    const json& cameras = Member(document, "cameras", "an object {name: {R, t, center}}");
    for (const auto& name : KeysInFileOrder(path, "cameras")) calibration->poses.push_back(PoseOf(name, cameras[name]));
    if (document.contains("failed")) {
      const json& failed = Member(document, "failed", "an object {name: reason}");
      for (const auto& name : KeysInFileOrder(path, "failed")) {
        calibration->failed.emplace_back(name, StringValue(failed[name], "failed." + name));
      }
    }
  } catch (const std::invalid_argument& error) {
    throw InputError(path.string() + ": " + error.what());
  }
}

CameraMetrics MetricsOf(const std::string& where, const json& entry) {
  static const std::set<std::string> known = {"mean_px", "std_px", "observations", "inliers", "track2_observations",
                                              "view_score", "failure", "rotation_sigma_deg", "centre_sigma", "weak"};
  static const std::set<std::string> required = {"mean_px", "std_px", "observations", "inliers",
                                                 "track2_observations", "view_score", "failure"};
  if (!entry.is_object()) throw std::invalid_argument(where + ": expected an object of metrics");
  std::vector<std::string> unknown, missing;
  for (const auto& item : entry.items()) {
    if (!known.count(item.key())) unknown.push_back(item.key());
  }
  for (const auto& name : required) {
    if (!entry.contains(name)) missing.push_back(name);
  }
  if (!unknown.empty() || !missing.empty()) {
    std::string problem = unknown.empty() ? "" : "unknown field(s) " + PythonList(unknown);
    if (!missing.empty()) problem += (problem.empty() ? "" : "; ") + std::string("missing field(s) ") + PythonList(missing);
    throw std::invalid_argument(where + ": " + problem);
  }
  constexpr long long kMaxCount = 1LL << 53;
  CameraMetrics m;
  m.mean_px = OptionalNonNegative(entry, "mean_px", where);
  m.std_px = OptionalNonNegative(entry, "std_px", where);
  m.observations = IntegerValue(entry["observations"], where + ".observations", 0, kMaxCount);
  m.inliers = IntegerValue(entry["inliers"], where + ".inliers", 0, kMaxCount);
  m.track2_observations = IntegerValue(entry["track2_observations"], where + ".track2_observations", 0, kMaxCount);
  m.view_score = IntegerValue(entry["view_score"], where + ".view_score", 0, kMaxCount);
  if (!entry["failure"].is_null()) m.failure = StringValue(entry["failure"], where + ".failure");
  m.rotation_sigma_deg = OptionalNonNegative(entry, "rotation_sigma_deg", where);
  m.centre_sigma = OptionalNonNegative(entry, "centre_sigma", where);
  if (entry.contains("weak")) m.weak = BoolValue(entry["weak"], where + ".weak");
  return m;
}

Plane PlaneOf(const std::string& where, const json& entry) {
  if (!entry.is_object() || entry.size() != 3 || !entry.contains("normal") || !entry.contains("offset") ||
      !entry.contains("points")) {
    throw std::invalid_argument(where + ": expected an object with normal, offset and points");
  }
  return {VectorOf(entry["normal"], where + ".normal"), NumberValue(entry["offset"], where + ".offset"),
          IntegerValue(entry["points"], where + ".points", 0, 1LL << 53)};
}

void ReadMetrics(const fs::path& path, Calibration* calibration) {
  const json document = ReadSchemaJson(path, "metrics", 1);
  try {
    const json& cameras = Member(document, "cameras", "an object {name: metrics}");
    for (const auto& name : KeysInFileOrder(path, "cameras")) {
      calibration->metrics.emplace_back(name, MetricsOf("cameras." + name, cameras[name]));
    }
    const json model = document.value("model", json("coplanar"));
    if (!model.is_string() || !kModels.count(model.get<std::string>())) {
      throw std::invalid_argument("model must be one of ['free', 'coplanar'], got " + Describe(model));
    }
    calibration->model = model.get<std::string>();
    const json order = document.value("registration_order", json::array());
    if (!order.is_array()) throw std::invalid_argument("registration_order: expected a list of camera names");
    for (const auto& name : order) {
      if (!name.is_string()) throw std::invalid_argument("registration_order: expected a list of camera names");
      calibration->registration_order.push_back(name.get<std::string>());
    }
    calibration->floor_rms = NonNegative(document.value("floor_rms", json(0.0)), "floor_rms");
    const json planes = document.value("planes", json::array());
    if (!planes.is_array()) throw std::invalid_argument("planes: expected a list");
    for (std::size_t k = 0; k < planes.size(); ++k) {
      calibration->planes.push_back(PlaneOf("planes[" + std::to_string(k) + "]", planes[k]));
    }
  } catch (const std::invalid_argument& error) {
    throw InputError(path.string() + ": " + error.what());
  }
}

void ReadPoints(const fs::path& path, Calibration* calibration) {
  std::ifstream in(path, std::ios::binary);
  if (!fs::is_regular_file(path) || !in) throw InputError(path.string() + ": no such file");
  const std::string schema = "calibproj.points/1";
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    lines.push_back(line);
  }
  bool tagged = false;
  for (std::size_t k = 0; k < std::min<std::size_t>(4, lines.size()); ++k) tagged |= lines[k] == "comment schema " + schema;
  if (lines.empty() || lines[0] != "ply" || !tagged) {
    throw InputError(path.string() + ": not a calibproj points file (" + schema + ")");
  }
  const auto end = std::find(lines.begin(), lines.end(), "end_header");
  long long count = -1;
  for (auto line = lines.begin(); line != end && count < 0; ++line) {
    std::istringstream words(*line);
    std::string element, vertex;
    if (line->rfind("element vertex", 0) == 0 && (words >> element >> vertex >> count)) break;
    count = -1;
  }
  if (end == lines.end() || count < 0) {
    throw InputError(path.string() + ": malformed PLY header (no 'element vertex N' before 'end_header')");
  }
  const auto rows = static_cast<long long>(lines.end() - end - 1);
  if (rows != count) {
    throw InputError(path.string() + ": " + std::to_string(count) + " vertices declared, " + std::to_string(rows) +
                     " found");
  }
  calibration->points.resize(count, 3);
  std::set<std::int64_t> seen;
  for (long long p = 0; p < count; ++p) {
    std::istringstream words(*(end + 1 + p));
    double x, y, z, id;
    std::string extra;
    if (!(words >> x >> y >> z >> id) || (words >> extra)) {
      throw InputError(path.string() + ": malformed vertex (expected 4 numbers: x y z id)");
    }
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z) || !std::isfinite(id)) {
      throw InputError(path.string() + ": a vertex is not finite");
    }
    if (id != std::floor(id) || id < 0.0 || id >= 9007199254740992.0) {
      throw InputError(path.string() + ": point ids must be non-negative integers");
    }
    if (!seen.insert(static_cast<std::int64_t>(id)).second) throw InputError(path.string() + ": a point id appears twice");
    calibration->points.row(p) << x, y, z;
    calibration->point_ids.push_back(static_cast<std::int64_t>(id));
  }
}

}  // namespace

Calibration ReadCalibration(const fs::path& directory) {
  if (!fs::is_directory(directory)) throw InputError(directory.string() + ": no such results folder");
  Calibration calibration;
  ReadPoses(directory / "camera_poses.json", &calibration);
  ReadMetrics(directory / "metrics.json", &calibration);
  ReadPoints(directory / "points.ply", &calibration);
  return calibration;
}

}  // namespace calibproj::formats
