// Reading a results folder's camera_poses.json, metrics.json and points.ply back into a
// Calibration, with the checks (and the messages) of the Python package's readers.

#include <Eigen/Dense>
#include <cmath>
#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <iterator>
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

constexpr double kRotationTolerance = 1e-6;  // |R R^T - I| a rotation read from a file may show
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
std::vector<std::string> KeysInFileOrder(const nlohmann::ordered_json& document, const std::string& member) {
  std::vector<std::string> keys;
  const auto found = document.find(member);
  if (found == document.end() || !found->is_object()) return keys;
  for (const auto& item : found->items()) keys.push_back(item.key());
  return keys;
}

const json& Member(const json& object, const std::string& key, const std::string& expected) {
  const auto found = object.find(key);
  if (found == object.end() || !found->is_object()) throw std::invalid_argument(key + ": expected " + expected);
  return *found;
}

// The pose of cameras.<name>; sets *weak to its "weak" flag.
CameraPose PoseOf(const std::string& name, const json& entry, bool* weak) {
  const std::string where = "cameras." + name;
  if (!entry.is_object() || !entry.contains("R") || !entry.contains("t")) {
    throw std::invalid_argument(where + ": expected an object with R (3x3) and t (3)");
  }
  CameraPose pose{name, RotationOf(entry["R"], where + ".R"), VectorOf(entry["t"], where + ".t")};
  if (entry.contains("center")) VectorOf(entry["center"], where + ".center");
  *weak = entry.contains("weak") && BoolValue(entry["weak"], where + ".weak");
  OptionalNonNegative(entry, "rotation_sigma_deg", where);
  OptionalNonNegative(entry, "centre_sigma", where);
  const double off = (pose.R * pose.R.transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (!(off <= kRotationTolerance) || pose.R.determinant() < 0.0) {
    throw std::invalid_argument(where + ": R is not a rotation matrix");
  }
  return pose;
}

// The poses of a file of `kind` (or of a kind `also_accepted`: camera_poses and truth
// both write {unit, frame, cameras: {name: {R, t, center}}, failed}).
CameraPoses PosesOfFile(const fs::path& path, const std::string& kind,
                        const std::vector<std::string>& also_accepted = {}) {
  const nlohmann::ordered_json ordered = ReadOrderedSchemaJson(path, kind, 1, also_accepted);
  const json document(ordered);
  CameraPoses out;
  out.source = path.string();
  try {
    const auto unit = document.find("unit");
    if (unit == document.end() || !unit->is_string() || !kUnits.count(unit->get<std::string>())) {
      throw std::invalid_argument("unit must be one of ['arbitrary', 'm'], got " +
                                  (unit == document.end() ? std::string("null") : Describe(*unit)));
    }
    out.unit = unit->get<std::string>();
    const auto frame = document.find("frame");
    if (frame != document.end() && *frame != "floor") {
      throw std::invalid_argument("frame must be 'floor', got " + Describe(*frame));
    }
    const json& cameras = Member(document, "cameras", "an object {name: {R, t, center}}");
    for (const auto& name : KeysInFileOrder(ordered, "cameras")) {
      bool weak = false;
      out.poses.push_back(PoseOf(name, cameras[name], &weak));
      if (weak) out.weak.push_back(name);
    }
    if (document.contains("failed")) {
      const json& failed = Member(document, "failed", "an object {name: reason}");
      for (const auto& name : KeysInFileOrder(ordered, "failed")) {
        out.failed.emplace_back(name, StringValue(failed[name], "failed." + name));
      }
    }
  } catch (const std::invalid_argument& error) {
    throw InputError(path.string() + ": " + error.what());
  }
  return out;
}

void ReadPoses(const fs::path& path, Calibration* calibration) {
  CameraPoses poses = PosesOfFile(path, "camera_poses");
  calibration->poses = std::move(poses.poses);
  calibration->failed = std::move(poses.failed);
  calibration->unit = std::move(poses.unit);
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
    if (!missing.empty()) {
      problem += (problem.empty() ? "" : "; ") + std::string("missing field(s) ") + PythonList(missing);
    }
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
  const nlohmann::ordered_json ordered = ReadOrderedSchemaJson(path, "metrics", 1);
  const json document(ordered);
  try {
    const json& cameras = Member(document, "cameras", "an object {name: metrics}");
    for (const auto& name : KeysInFileOrder(ordered, "cameras")) {
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

// The lines of a text as Python's str.splitlines() cuts them (\n, \r\n, \r, \v, \f,
// \x1c-\x1e, U+0085, U+2028, U+2029).
std::vector<std::string> SplitLines(const std::string& text) {
  std::vector<std::string> lines;
  std::string line;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    std::size_t skip = 0;
    if (c == '\r' && i + 1 < text.size() && text[i + 1] == '\n') {
      skip = 1;
    } else if (c == '\n' || c == '\r' || c == '\v' || c == '\f' || c == '\x1c' || c == '\x1d' || c == '\x1e') {
      skip = 0;
    } else if (text.compare(i, 2, "\xc2\x85") == 0) {
      skip = 1;
    } else if (text.compare(i, 3, "\xe2\x80\xa8") == 0 || text.compare(i, 3, "\xe2\x80\xa9") == 0) {
      skip = 2;
    } else {
      line += c;
      continue;
    }
    lines.push_back(line);
    line.clear();
    i += skip;
  }
  if (!line.empty()) lines.push_back(line);
  return lines;
}

// The white-space separated words of a line (spaces and tabs).
std::vector<std::string> Words(const std::string& line) {
  std::istringstream in(line);
  std::vector<std::string> words;
  for (std::string word; in >> word;) words.push_back(word);
  return words;
}

// A number as Python's float() reads one (no hexadecimal); false otherwise.
bool ParseFloat(const std::string& word, double* value) {
  if (word.find_first_of("xX(") != std::string::npos) return false;
  char* end = nullptr;
  *value = std::strtod(word.c_str(), &end);
  return !word.empty() && end == word.c_str() + word.size();
}

void ReadPoints(const fs::path& path, Calibration* calibration) {
  const std::string schema = "calibproj.points/1";
  std::ifstream in(path, std::ios::binary);
  if (!fs::is_regular_file(path) || !in) throw InputError(path.string() + ": no such file");
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (InvalidUtf8At(text) != std::string::npos) {
    throw InputError(path.string() + ": not a calibproj points file (" + schema + "): not UTF-8 text");
  }
  const std::vector<std::string> lines = SplitLines(text);
  bool tagged = false;
  for (std::size_t k = 0; k < std::min<std::size_t>(4, lines.size()); ++k) {
    tagged |= lines[k] == "comment schema " + schema;
  }
  if (lines.empty() || lines[0] != "ply" || !tagged) {
    throw InputError(path.string() + ": not a calibproj points file (" + schema + ")");
  }
  const auto end = std::find(lines.begin(), lines.end(), "end_header");
  const auto declaration = std::find_if(lines.begin(), end, [](const std::string& line) {
    return line.rfind("element vertex", 0) == 0;
  });
  long long count = -1;
  if (end != lines.end() && declaration != end) {
    const std::vector<std::string> words = Words(*declaration);
    char* stop = nullptr;
    if (words.size() >= 3) count = std::strtoll(words[2].c_str(), &stop, 10);
    if (words.size() < 3 || stop != words[2].c_str() + words[2].size() || words[2].empty()) count = -2;
  }
  if (count == -1 || count == -2) {
    throw InputError(path.string() + ": malformed PLY header (no 'element vertex N' before 'end_header')");
  }
  const auto rows = static_cast<long long>(lines.end() - end - 1);
  if (count < 0 || rows != count) {
    throw InputError(path.string() + ": " + std::to_string(count) + " vertices declared, " + std::to_string(rows) +
                     " found");
  }
  calibration->points.resize(count, 3);
  std::vector<double> ids(count);
  for (long long p = 0; p < count; ++p) {
    const std::vector<std::string> words = Words(*(end + 1 + p));
    double values[4];
    bool numbers = words.size() == 4;
    for (std::size_t k = 0; numbers && k < 4; ++k) numbers = ParseFloat(words[k], &values[k]);
    if (!numbers) throw InputError(path.string() + ": malformed vertex (expected 4 numbers: x y z id)");
    calibration->points.row(p) << values[0], values[1], values[2];
    ids[p] = values[3];
  }
  if (!calibration->points.allFinite() ||
      !std::all_of(ids.begin(), ids.end(), [](double id) { return std::isfinite(id); })) {
    throw InputError(path.string() + ": a vertex is not finite");
  }
  std::set<std::int64_t> seen;
  for (const double id : ids) {
    if (id != std::floor(id) || id < 0.0 || id >= 9007199254740992.0) {
      throw InputError(path.string() + ": point ids must be non-negative integers");
    }
  }
  for (const double id : ids) {
    if (!seen.insert(static_cast<std::int64_t>(id)).second) {
      throw InputError(path.string() + ": a point id appears twice");
    }
    calibration->point_ids.push_back(static_cast<std::int64_t>(id));
  }
}

}  // namespace

CameraPoses ReadCameraPoses(const fs::path& path) {
  // A simulation's truth.json holds its cameras as camera_poses.json does.
  return PosesOfFile(path, "camera_poses", {"truth"});
}

Calibration ReadCalibration(const fs::path& directory) {
  if (!fs::is_directory(directory)) throw InputError(directory.string() + ": no such results folder");
  Calibration calibration;
  ReadPoses(directory / "camera_poses.json", &calibration);
  ReadMetrics(directory / "metrics.json", &calibration);
  ReadPoints(directory / "points.ply", &calibration);
  return calibration;
}

}  // namespace calibproj::formats
