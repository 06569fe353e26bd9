#pragma once
// Per-camera intrinsics files: ours (calibproj.intrinsics/1 JSON), the reference code's
// JSON (sensors.RGB.intrinsics.data) and OpenCV YAML/XML, as the Python package reads them.

#include <Eigen/Core>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <map>
#include <string>
#include <vector>

#include "calibproj/formats/camera_intrinsics.h"

namespace calibproj::formats {

// One intrinsics file in any supported format, named `name` (empty: the file stem);
// InputError naming the file and the problem, with the Python reader's messages.
CameraIntrinsics ReadIntrinsics(const std::filesystem::path& path, const std::string& name = "");

// Writes our format (calibproj.intrinsics/1) atomically, as the Python package writes
// it; an image size not known (the reference code's JSON) is written as null. The
// entries of `extra` (an object: how the intrinsics were measured, their uncertainty)
// follow the format's own; readers pass over them.
void WriteIntrinsics(const std::filesystem::path& path, const CameraIntrinsics& intrinsics,
                     const nlohmann::ordered_json& extra = nlohmann::ordered_json::object());

// The body of our format ({camera, resolution, K, dist}; resolution null when not known)
// as WriteIntrinsics writes it.
nlohmann::ordered_json IntrinsicsBody(const CameraIntrinsics& intrinsics);

// The body of our format ({resolution, K, dist}, resolution null when not known);
// std::invalid_argument with the problem.
CameraIntrinsics IntrinsicsFromDocument(const nlohmann::json& document, const std::string& name);

// Why a camera has no intrinsics in `folder`: "<folder>/<name>.json: no intrinsics file for
// camera '<name>' (also looked for <name>.yaml, <name>.yml, <name>.xml)".
std::string MissingIntrinsicsFile(const std::filesystem::path& folder, const std::string& name);

// The intrinsics files of a folder (.json, .yaml, .yml, .xml, the suffix in any case),
// sorted, keyed by camera name (the file stem; one file per camera, normally).
// InputError when the folder does not exist or holds no intrinsics file at all.
std::map<std::string, std::vector<std::filesystem::path>> IntrinsicsFilesIn(const std::filesystem::path& directory);

// The one intrinsics file of camera `name` in `directory` (the one lookup of both tools);
// InputError naming the folder, the missing file or the second file of that camera.
std::filesystem::path IntrinsicsFileOf(const std::filesystem::path& directory, const std::string& name);

// The intrinsics files of a folder, keyed by camera name (the file stem). A file that
// cannot be used (malformed, or a second file for one camera) fails its own camera only.
struct IntrinsicsDir {
  std::map<std::string, CameraIntrinsics> cameras;
  std::map<std::string, std::string> unusable;  // camera -> the file and its problem
};

// Throws InputError when the folder does not exist or holds no intrinsics file at all.
IntrinsicsDir LoadIntrinsicsDir(const std::filesystem::path& directory);

}  // namespace calibproj::formats
