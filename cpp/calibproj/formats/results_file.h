#pragma once
// camera_poses.json, metrics.json and points.ply, in the layout the Python Calibration
// writes (calibproj/calibration.py, calibproj/io/poses.py).

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "calibproj/registration/result.h"

namespace calibproj::formats {

struct ResultFiles {
  std::vector<std::string> cameras;         // names of the registration's cameras
  std::vector<std::int64_t> point_ids;      // ids of the registration's points
  std::vector<std::pair<std::string, std::string>> left_out;  // cameras failed before registration
  std::string model;
};

// Files that a results folder holds; an existing one is only replaced with force.
extern const std::vector<std::string> kResultFiles;

void WriteResults(const std::filesystem::path& out, const registration::RegistrationResult& result,
                  const ResultFiles& names);

}  // namespace calibproj::formats
