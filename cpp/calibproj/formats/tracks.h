#pragma once
// Tracks: which cameras saw which point, and where (undistorted pixels). The one type
// the core, calibproj-native and the Python package (bound as calibproj.formats.tracks.Tracks)
// share.
//
// A point is one projected MSM, identified by (array, marker) with point id
// array * markers_per_array + marker (docs/conventions.md), or, for evaluation data,
// any non-negative integer id (markers_per_array then unset). Observations are stored
// flat, one row per (camera, point), ordered by camera then point id: what a bundle
// adjuster takes.

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "calibproj/ba/bundle_adjuster.h"

namespace calibproj::formats {

struct Tracks {
  std::vector<std::string> cameras;     // every camera, even one that saw nothing
  std::vector<std::int64_t> point_ids;  // sorted, unique
  Eigen::VectorXi camera_index;         // per observation
  Eigen::VectorXi point_index;          // per observation, into point_ids
  ba::PixelMatrix xy;                   // per observation
  std::optional<int> markers_per_array;

  // std::invalid_argument unless every observation has a camera, a point and a pixel.
  void Check() const;

  int NumObservations() const { return static_cast<int>(camera_index.size()); }
  // std::invalid_argument naming the cameras when there is no such camera.
  int CameraPosition(const std::string& name) const;
  // Observations per camera, in camera order.
  std::vector<int> CountsPerCamera() const;
  // Cameras that saw each point.
  std::vector<int> TrackLengths() const;
  // (P, C): point p seen by camera c.
  Eigen::Matrix<bool, Eigen::Dynamic, Eigen::Dynamic> Visibility() const;
  // (C, C): points shared by every pair of cameras; the diagonal is per-camera counts.
  Eigen::MatrixXi PairCounts() const;
  // Points shared by every pair of cameras (a before b), zeros included.
  std::map<std::pair<std::string, std::string>, int> PairCountsByName() const;
  // The point ids and pixels one camera saw.
  std::pair<std::vector<std::int64_t>, ba::PixelMatrix> ObservationsOf(const std::string& camera) const;

  // The same observations at other pixels (one row per observation); std::invalid_argument
  // for another number of rows or a pixel not finite.
  Tracks WithPixels(const ba::PixelMatrix& pixels) const;
  // The observations where `keep` is true, of the cameras `names` (in that order; all
  // cameras when null); points nobody sees any more are dropped.
  Tracks Select(const std::vector<bool>& keep, const std::vector<std::string>* names = nullptr) const;
  // Without the named cameras; std::invalid_argument naming any unknown one.
  Tracks WithoutCameras(const std::vector<std::string>& names) const;
  // Only the named cameras, in the given order; std::invalid_argument naming any unknown one.
  Tracks OnlyCameras(const std::vector<std::string>& names) const;
  Tracks WithoutPoints(const std::vector<std::int64_t>& ids) const;
  // Only the points seen by at least `min_cameras` cameras.
  Tracks WithMinTrackLength(int min_cameras) const;
};

// Per observation its camera's index into `cameras`, from indices or from names;
// std::invalid_argument for an index out of range or a name not in `cameras`.
std::vector<int> CameraIndices(const std::vector<std::string>& cameras, const std::vector<std::int64_t>& index);
std::vector<int> CameraIndices(const std::vector<std::string>& cameras, const std::vector<std::string>& names);

// Builds tracks from unordered observations: std::invalid_argument for duplicate camera
// names, a camera index out of range, a negative point id, a pixel not finite, a point
// seen twice by one camera, or markers per array not positive. Sorts and indexes points.
Tracks MakeTracks(std::vector<std::string> cameras, const std::vector<int>& camera, const std::vector<std::int64_t>& ids,
                  const std::vector<Eigen::Vector2d>& xy, std::optional<int> markers_per_array);

// The observations of both (cameras: `first`'s, then those only `second` has).
// std::invalid_argument when they share a point id or differ in markers per array:
// merged tracks come from two projections of one sequence family, whose point ids are
// disjoint by construction (a densified sequence shows only arrays the first lacks).
Tracks MergeTracks(const Tracks& first, const Tracks& second);

}  // namespace calibproj::formats
