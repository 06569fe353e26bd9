#include "calibproj/formats/intrinsics_file.h"

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/core/eigen.hpp>

#include "calibproj/common/limits.h"
#include "calibproj/formats/files.h"

namespace calibproj::formats {

namespace fs = std::filesystem;

namespace {

const std::vector<std::string> kYamlSuffixes = {".yaml", ".yml", ".xml"};
const std::vector<size_t> kDistortionLengths = {4, 5, 8, 12, 14};

std::string Lower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return std::tolower(c); });
  return text;
}

void Check(const fs::path& path, const CameraIntrinsics& in) {
  const Eigen::Matrix3d& K = in.K;
  bool finite = K.allFinite();
  for (double d : in.dist) finite = finite && std::isfinite(d);
  std::string problem;
  if (!finite) {
    problem = "K and dist must be finite numbers";
  } else if (K(0, 0) <= 0 || K(1, 1) <= 0) {
    problem = "focal lengths must be positive";
  } else if (K(0, 1) != 0 || K(1, 0) != 0 || K(2, 0) != 0 || K(2, 1) != 0 || K(2, 2) != 1) {
    problem = "K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]";
  } else if (std::find(kDistortionLengths.begin(), kDistortionLengths.end(), in.dist.size()) ==
             kDistortionLengths.end()) {
    problem = "dist must have 4, 5, 8, 12, 14 coefficients, got " + std::to_string(in.dist.size());
  } else if (in.has_resolution && (in.width <= 0 || in.height <= 0 || in.width != std::floor(in.width) ||
                                   in.height != std::floor(in.height))) {
    problem = "resolution must be two positive integers [width, height]";
  } else if (!(in.ImageWidth() > 0 && in.ImageWidth() <= limits::kMaxImageSide && in.ImageHeight() > 0 &&
               in.ImageHeight() <= limits::kMaxImageSide)) {
    // Without a resolution the principal point gives the image size.
    problem = "image size must be at most " + std::to_string(limits::kMaxImageSide) + " pixels per side";
  }
  if (!problem.empty()) throw InputError(path.string() + ": intrinsics of '" + in.name + "': " + problem);
}

Eigen::Matrix3d MatrixFromJson(const fs::path& path, const nlohmann::json& value) {
  std::vector<double> flat;
  const auto append = [&](const nlohmann::json& v) {
    if (!v.is_number()) throw InputError(path.string() + ": K and dist must be numbers");
    flat.push_back(v.get<double>());
  };
  if (!value.is_array()) throw InputError(path.string() + ": K and dist must be numbers");
  for (const auto& row : value) {
    if (row.is_array()) {
      for (const auto& v : row) append(v);
    } else {
      append(row);
    }
  }
  if (flat.size() != 9) throw InputError(path.string() + ": K must have 9 values (3x3), got " + std::to_string(flat.size()));
  Eigen::Matrix3d K;
  for (int i = 0; i < 9; ++i) K(i / 3, i % 3) = flat[i];
  return K;
}

std::vector<double> VectorFromJson(const fs::path& path, const nlohmann::json& value, const std::string& what) {
  std::vector<double> out;
  if (value.is_null()) return out;
  if (!value.is_array()) throw InputError(path.string() + ": " + what + " must be numbers");
  for (const auto& v : value) {
    if (v.is_array()) {
      for (const auto& w : v) {
        if (!w.is_number()) throw InputError(path.string() + ": " + what + " must be numbers");
        out.push_back(w.get<double>());
      }
    } else if (v.is_number()) {
      out.push_back(v.get<double>());
    } else {
      throw InputError(path.string() + ": " + what + " must be numbers");
    }
  }
  return out;
}

CameraIntrinsics FromJson(const fs::path& path) {
  const nlohmann::json document = ReadJson(path);
  CameraIntrinsics in;
  in.name = path.stem().string();
  if (document.is_object() && document.contains("sensors")) {
    try {
      const auto& rgb = document.at("sensors").at("RGB");
      in.K = MatrixFromJson(path, rgb.at("intrinsics").at("data"));
      in.dist = VectorFromJson(path, rgb.at("distortionCoefficients").at("data"), "K and dist");
    } catch (const nlohmann::json::exception&) {
      throw InputError(path.string() +
                       ": expected sensors.RGB.intrinsics.data and sensors.RGB.distortionCoefficients.data");
    }
    return in;
  }
  const nlohmann::json ours = ReadSchemaJson(path, "intrinsics", 1);
  for (const char* key : {"resolution", "K"}) {
    if (!ours.contains(key)) throw InputError(path.string() + ": missing field '" + key + "'");
  }
  in.K = MatrixFromJson(path, ours.at("K"));
  in.dist = VectorFromJson(path, ours.contains("dist") ? ours.at("dist") : nlohmann::json::array(), "K and dist");
  const std::vector<double> resolution = VectorFromJson(path, ours.at("resolution"), "resolution");
  if (resolution.size() != 2) throw InputError(path.string() + ": resolution must be [width, height]");
  in.has_resolution = true;
  in.width = resolution[0];
  in.height = resolution[1];
  return in;
}

cv::Mat FirstMatrix(const cv::FileStorage& storage, const std::vector<std::string>& keys) {
  for (const auto& key : keys) {
    const cv::FileNode node = storage[key];
    if (node.empty()) continue;
    cv::Mat matrix;
    if (node.isMap()) {
      node >> matrix;
    } else {
      std::vector<double> values;
      node >> values;
      matrix = cv::Mat(values, true);
    }
    return matrix;
  }
  return {};
}

CameraIntrinsics FromOpenCvStorage(const fs::path& path) {
  cv::FileStorage storage;
  try {
    storage.open(path.string(), cv::FileStorage::READ);
  } catch (const cv::Exception&) {
  }
  if (!storage.isOpened()) throw InputError(path.string() + ": not a readable OpenCV YAML/XML file");
  CameraIntrinsics in;
  in.name = path.stem().string();
  const cv::Mat K = FirstMatrix(storage, {"camera_matrix", "K", "cameraMatrix"});
  const cv::Mat dist = FirstMatrix(storage, {"distortion_coefficients", "D", "dist_coeffs", "distCoeffs"});
  if (K.empty()) throw InputError(path.string() + ": missing camera_matrix (or K)");
  if (dist.empty()) throw InputError(path.string() + ": missing distortion_coefficients (or D)");
  if (K.total() != 9) throw InputError(path.string() + ": K must have 9 values (3x3), got " + std::to_string(K.total()));
  cv::Mat K64, dist64;
  K.reshape(1, 3).convertTo(K64, CV_64F);
  dist.reshape(1, 1).convertTo(dist64, CV_64F);
  cv::cv2eigen(K64, in.K);
  in.dist.assign(dist64.begin<double>(), dist64.end<double>());
  const cv::FileNode width = storage["image_width"], height = storage["image_height"];
  if (!width.empty() && !height.empty()) {
    in.has_resolution = true;
    in.width = width.real();
    in.height = height.real();
  }
  return in;
}

}  // namespace

CameraIntrinsics ReadIntrinsics(const fs::path& path) {
  if (!fs::is_regular_file(path)) throw InputError(path.string() + ": no such intrinsics file");
  const std::string suffix = Lower(path.extension().string());
  CameraIntrinsics in;
  // Whatever the readers throw names the file.
  try {
    if (std::find(kYamlSuffixes.begin(), kYamlSuffixes.end(), suffix) != kYamlSuffixes.end()) {
      in = FromOpenCvStorage(path);
    } else if (suffix == ".json") {
      in = FromJson(path);
    } else {
      throw InputError(path.string() + ": unknown intrinsics format (expected .json, .yaml, .yml or .xml)");
    }
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& error) {
    throw InputError(path.string() + ": not a readable intrinsics file (" + error.what() + ")");
  }
  if (in.dist.empty()) in.dist.assign(5, 0.0);
  Check(path, in);
  return in;
}

IntrinsicsDir LoadIntrinsicsDir(const fs::path& directory) {
  if (!fs::is_directory(directory)) throw InputError(directory.string() + ": no such intrinsics directory");
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(directory)) {
    const std::string suffix = Lower(entry.path().extension().string());
    if (entry.is_regular_file() && (suffix == ".json" || std::find(kYamlSuffixes.begin(), kYamlSuffixes.end(),
                                                                   suffix) != kYamlSuffixes.end())) {
      files.push_back(entry.path());
    }
  }
  std::sort(files.begin(), files.end());
  if (files.empty()) throw InputError(directory.string() + ": no intrinsics files (*.json, *.yaml, *.yml, *.xml)");
  IntrinsicsDir out;
  for (const auto& path : files) {
    const std::string name = path.stem().string();
    if (out.cameras.count(name) || out.unusable.count(name)) {
      out.cameras.erase(name);
      out.unusable[name] = path.string() + ": a second intrinsics file for camera '" + name + "'";
      continue;
    }
    try {
      out.cameras[name] = ReadIntrinsics(path);
    } catch (const InputError& error) {
      out.unusable[name] = error.what();
    }
  }
  return out;
}

}  // namespace calibproj::formats
