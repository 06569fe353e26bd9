#pragma once
// The expected triangulation error over the working volume, and uncertainty.json.
//
// The volume: the floor's extent that the projection covered (its points' bounding box)
// from the floor to 2 m, sampled on a grid of cells at heights that matter in an
// operating room (floor, table at 0.9 m, head at 1.7 m, ...). A calibration without a
// metric scale takes those heights as shares of 2 m in the volume the check uses (70 %
// of the highest camera's height).

#include <Eigen/Core>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "calibproj/formats/calibration.h"
#include "calibproj/formats/intrinsics_file.h"
#include "calibproj/uncertainty/triangulation.h"

namespace calibproj::uncertainty {

// Heights of the map's levels in metres (scaled as above without a metric scale).
const std::vector<double>& LevelHeightsM();
constexpr double kTableHeightM = 0.9;
constexpr int kCellsAlongLongerSide = 24;

struct VolumeMap {
  std::vector<double> xs, ys, zs;  // cell centres, calibration unit
  // Per level, row (y) and column (x): the triangulation uncertainty of the cell centre.
  std::vector<PointUncertainty> cells;
  const PointUncertainty& At(size_t level, size_t row, size_t column) const {
    return cells[(level * ys.size() + row) * xs.size() + column];
  }
  // The table-height point above the middle of the projection and its uncertainty.
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  PointUncertainty at_centre;
};

VolumeMap MapVolume(const UncertaintyModel& model, const formats::Calibration& calibration);

extern const char* const kUncertaintyFile;  // "uncertainty.json"

// The file's text: gauge, per camera its noise and how far the volume's points may
// project (median and largest 1-sigma, px), the headline figures, the map, and the
// joint pose covariance the rest derives from (read back by ReadPoseUncertainty).
std::string UncertaintyJson(const formats::Calibration& calibration, const UncertaintyModel& model,
                            const VolumeMap& map);

// Writes uncertainty.json into `directory` atomically when the calibration carries a
// pose covariance; false (nothing written) when it does not.
bool WriteUncertainty(const std::filesystem::path& directory, const formats::Calibration& calibration,
                      const std::map<std::string, formats::CameraIntrinsics>& intrinsics);

// The joint pose covariance of a results folder's uncertainty.json; InputError naming
// the file and the problem.
registration::PoseUncertainty ReadPoseUncertainty(const std::filesystem::path& directory);

// The joint pose covariance stored beside `calibration` in its results folder
// `directory`, when its uncertainty.json is there and is of those cameras; else empty,
// with why in *warning (left empty when the folder has no such file).
registration::PoseUncertainty StoredPoseUncertainty(const std::filesystem::path& directory,
                                                    const formats::Calibration& calibration, std::string* warning);

}  // namespace calibproj::uncertainty
