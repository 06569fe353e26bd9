#include "calibproj/formats/intrinsics_file.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <stdexcept>
#include <opencv2/core.hpp>
#include <opencv2/core/eigen.hpp>

#include "calibproj/common/limits.h"
#include "calibproj/formats/files.h"
#include "calibproj/formats/json_values.h"

namespace calibproj::formats {

namespace fs = std::filesystem;

namespace {

const std::vector<std::string> kYamlSuffixes = {".yaml", ".yml", ".xml"};

std::string Lower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return std::tolower(c); });
  return text;
}

// [width, height]: two positive integral numbers.
void SetResolution(const nlohmann::json& value, CameraIntrinsics* in) {
  bool valid = value.is_array() && value.size() == 2;
  for (size_t k = 0; valid && k < 2; ++k) {
    const nlohmann::json& side = value[k];
    valid = side.is_number() && std::isfinite(side.get<double>()) && side.get<double>() > 0 &&
            side.get<double>() == std::floor(side.get<double>());
  }
  if (!valid) {
    throw std::invalid_argument("resolution must be two positive integers [width, height], got " + Describe(value));
  }
  in->has_resolution = true;
  in->width = value[0].get<double>();
  in->height = value[1].get<double>();
}

// The values of a file, checked here for every format ("K: expected numbers, ...").
CameraIntrinsics Build(const std::string& name, const nlohmann::json& K, const nlohmann::json& dist,
                       const nlohmann::json* resolution) {
  CameraIntrinsics in;
  in.name = name;
  const NumberArray K_values = NumbersOf(K, "K");
  if (!dist.is_null()) in.dist = NumbersOf(dist, "dist").values;
  if (K_values.values.size() != 9) {
    throw std::invalid_argument("K must have 9 values (3x3), got " + std::to_string(K_values.values.size()));
  }
  for (int i = 0; i < 9; ++i) in.K(i / 3, i % 3) = K_values.values[i];
  if (resolution) SetResolution(*resolution, &in);
  if (in.dist.empty()) in.dist.assign(5, 0.0);
  if (const std::string problem = IntrinsicsProblem(in); !problem.empty()) {
    throw std::invalid_argument("intrinsics of " + PythonRepr(name) + ": " + problem);
  }
  return in;
}

CameraIntrinsics FromReferenceJson(const nlohmann::json& document, const std::string& name) {
  const auto member = [](const nlohmann::json* node, const char* key) -> const nlohmann::json* {
    if (node == nullptr || !node->is_object() || !node->contains(key)) return nullptr;
    return &node->at(key);
  };
  const nlohmann::json* rgb = member(member(&document, "sensors"), "RGB");
  const nlohmann::json* K = member(member(rgb, "intrinsics"), "data");
  const nlohmann::json* dist = member(member(rgb, "distortionCoefficients"), "data");
  if (!K || !dist) {
    throw std::invalid_argument("expected sensors.RGB.intrinsics.data and sensors.RGB.distortionCoefficients.data");
  }
  return Build(name, *K, *dist, nullptr);
}

}  // namespace

CameraIntrinsics IntrinsicsFromDocument(const nlohmann::json& document, const std::string& name) {
  if (!document.is_object()) throw std::invalid_argument("expected an object with resolution, K and dist");
  for (const char* key : {"resolution", "K"}) {
    if (!document.contains(key)) throw std::invalid_argument(std::string("missing field '") + key + "'");
  }
  const nlohmann::json& resolution = document.at("resolution");  // null: not known
  return Build(name, document.at("K"), document.contains("dist") ? document.at("dist") : nlohmann::json::array(),
               resolution.is_null() ? nullptr : &resolution);
}

namespace {

CameraIntrinsics FromOurJson(const fs::path& path, const std::string& name) {
  return IntrinsicsFromDocument(ReadSchemaJson(path, "intrinsics", 1), name);
}

// The first of `keys` in the file: an opencv-matrix, or a plain sequence of numbers.
std::optional<nlohmann::json> FirstMatrix(const cv::FileStorage& storage, const std::vector<std::string>& keys) {
  for (const auto& key : keys) {
    const cv::FileNode node = storage[key];
    if (node.empty()) continue;
    nlohmann::json values = nlohmann::json::array();
    if (node.isMap()) {
      cv::Mat matrix, doubles;
      node >> matrix;
      matrix.reshape(1, 1).convertTo(doubles, CV_64F);
      for (int i = 0; i < doubles.cols; ++i) values.push_back(doubles.at<double>(0, i));
    } else {
      for (const auto& item : node) values.push_back(item.real());
    }
    return values;
  }
  return std::nullopt;
}

CameraIntrinsics FromOpenCvStorage(const fs::path& path, const std::string& name) {
  cv::FileStorage storage;
  try {
    storage.open(path.string(), cv::FileStorage::READ);
  } catch (const cv::Exception&) {
  }
  if (!storage.isOpened()) throw std::invalid_argument("not a readable OpenCV YAML/XML file");
  const auto K = FirstMatrix(storage, {"camera_matrix", "K", "cameraMatrix"});
  const auto dist = FirstMatrix(storage, {"distortion_coefficients", "D", "dist_coeffs", "distCoeffs"});
  const cv::FileNode width = storage["image_width"], height = storage["image_height"];
  const bool sized = !width.empty() && !height.empty();
  const nlohmann::json resolution = sized ? nlohmann::json{width.real(), height.real()} : nlohmann::json();
  if (!K) throw std::invalid_argument("missing camera_matrix (or K)");
  if (!dist) throw std::invalid_argument("missing distortion_coefficients (or D)");
  return Build(name, *K, *dist, sized ? &resolution : nullptr);
}

}  // namespace

CameraIntrinsics ReadIntrinsics(const fs::path& path, const std::string& name) {
  if (!fs::is_regular_file(path)) throw InputError(path.string() + ": no such intrinsics file");
  const std::string suffix = Lower(path.extension().string());
  const std::string camera = name.empty() ? path.stem().string() : name;
  // Whatever the readers throw names the file.
  try {
    if (std::find(kYamlSuffixes.begin(), kYamlSuffixes.end(), suffix) != kYamlSuffixes.end()) {
      return FromOpenCvStorage(path, camera);
    }
    if (suffix != ".json") {
      throw std::invalid_argument("unknown intrinsics format (expected .json, .yaml, .yml or .xml)");
    }
    const nlohmann::json document = ReadJson(path);
    if (document.is_object() && document.contains("sensors")) return FromReferenceJson(document, camera);
    return FromOurJson(path, camera);
  } catch (const InputError&) {
    throw;
  } catch (const std::invalid_argument& error) {
    throw InputError(path.string() + ": " + error.what());
  } catch (const std::exception& error) {
    throw InputError(path.string() + ": not a readable intrinsics file (" + error.what() + ")");
  }
}

nlohmann::ordered_json IntrinsicsBody(const CameraIntrinsics& intrinsics) {
  nlohmann::ordered_json K = nlohmann::ordered_json::array();
  for (int r = 0; r < 3; ++r) K.push_back({intrinsics.K(r, 0), intrinsics.K(r, 1), intrinsics.K(r, 2)});
  nlohmann::ordered_json body = {
      {"camera", intrinsics.name},
      {"resolution", intrinsics.has_resolution ? nlohmann::ordered_json{static_cast<std::int64_t>(intrinsics.width),
                                                                        static_cast<std::int64_t>(intrinsics.height)}
                                               : nlohmann::ordered_json(nullptr)},
      {"K", K},
      {"dist", intrinsics.dist}};
  return body;
}

void WriteIntrinsics(const fs::path& path, const CameraIntrinsics& intrinsics, const nlohmann::ordered_json& extra) {
  nlohmann::ordered_json body = IntrinsicsBody(intrinsics);
  for (const auto& [key, value] : extra.items()) {
    if (!body.contains(key)) body[key] = value;
  }
  AtomicWrite(path, DumpSchemaJson("intrinsics", 1, body));
}

std::string MissingIntrinsicsFile(const fs::path& folder, const std::string& name) {
  std::string others;
  for (const auto& suffix : kYamlSuffixes) others += (others.empty() ? "" : ", ") + name + suffix;
  return (folder / (name + ".json")).string() + ": no intrinsics file for camera " + PythonRepr(name) +
         " (also looked for " + others + ")";
}

std::map<std::string, std::vector<fs::path>> IntrinsicsFilesIn(const fs::path& directory) {
  if (!fs::is_directory(directory)) throw InputError(directory.string() + ": no such intrinsics directory");
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(directory)) {
    const std::string suffix = Lower(entry.path().extension().string());
    if (entry.is_regular_file() && (suffix == ".json" || std::find(kYamlSuffixes.begin(), kYamlSuffixes.end(),
                                                                   suffix) != kYamlSuffixes.end())) {
      files.push_back(entry.path());
    }
  }
  if (files.empty()) throw InputError(directory.string() + ": no intrinsics files (*.json, *.yaml, *.yml, *.xml)");
  std::sort(files.begin(), files.end());
  std::map<std::string, std::vector<fs::path>> by_camera;
  for (const auto& path : files) by_camera[path.stem().string()].push_back(path);
  return by_camera;
}

namespace {

fs::path OnlyFile(const fs::path& directory, const std::string& name,
                  const std::map<std::string, std::vector<fs::path>>& files) {
  const auto found = files.find(name);
  if (found == files.end()) throw InputError(MissingIntrinsicsFile(directory, name));
  if (found->second.size() > 1) {
    throw InputError(found->second[1].string() + ": a second intrinsics file for camera " + PythonRepr(name));
  }
  return found->second.front();
}

}  // namespace

fs::path IntrinsicsFileOf(const fs::path& directory, const std::string& name) {
  return OnlyFile(directory, name, IntrinsicsFilesIn(directory));
}

IntrinsicsDir LoadIntrinsicsDir(const fs::path& directory) {
  const auto files = IntrinsicsFilesIn(directory);
  IntrinsicsDir out;
  for (const auto& [name, unused] : files) {
    try {
      out.cameras[name] = ReadIntrinsics(OnlyFile(directory, name, files));
    } catch (const InputError& error) {
      out.unusable[name] = error.what();
    }
  }
  return out;
}

}  // namespace calibproj::formats
