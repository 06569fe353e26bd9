#pragma once
// tracks.json (calibproj.tracks/1): per camera the undistorted pixels of the points it
// sees. Observations are ordered by camera, then point id, as the Python Tracks does,
// so both drive the registration with identical inputs.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "calibproj/ba/bundle_adjuster.h"

namespace calibproj::formats {

struct Tracks {
  std::vector<std::string> cameras;
  std::vector<std::int64_t> point_ids;  // sorted, unique
  Eigen::VectorXi camera_index;         // per observation
  Eigen::VectorXi point_index;          // per observation, into point_ids
  ba::PixelMatrix xy;                   // per observation
  std::optional<int> markers_per_array;

  // std::invalid_argument unless every observation has a camera, a point and a pixel.
  void Check() const;

  // The same tracks without the named cameras; points nobody sees any more are dropped.
  Tracks WithoutCameras(const std::vector<std::string>& names) const;
};

Tracks ReadTracks(const std::filesystem::path& path);

// The observations of both (cameras: `first`'s, then those only `second` has).
// std::invalid_argument when they share a point id or differ in markers per array:
// merged tracks come from two projections of one sequence family, whose point ids are
// disjoint by construction (a densified sequence shows only arrays the first lacks).
Tracks MergeTracks(const Tracks& first, const Tracks& second);

// Writes tracks.json atomically in the Python writer's layout: the header indented,
// then per camera its point ids and pixels on one line each (every camera listed,
// those without observations with empty lists).
// Atomically; std::invalid_argument naming the file when the tracks are inconsistent or
// a pixel is not finite (JSON has no NaN), the file then untouched.
void WriteTracks(const std::filesystem::path& path, const Tracks& tracks);

// Builds tracks from unordered observations (checks duplicates, sorts, indexes points).
Tracks MakeTracks(std::vector<std::string> cameras, const std::vector<int>& camera, const std::vector<std::int64_t>& ids,
                  const std::vector<Eigen::Vector2d>& xy, std::optional<int> markers_per_array);

}  // namespace calibproj::formats
