#pragma once
// A calibration as its results folder holds it, and its files: camera_poses.json,
// metrics.json and points.ply (docs/conventions.md). The Python package
// (calibproj.formats.calibration) and calibproj-native both write them through here, so both
// write the same bytes.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "calibproj/registration/result.h"

namespace calibproj::formats {

// World-to-camera pose in the floor frame: x_cam = R X + t.
struct CameraPose {
  std::string name;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();

  Eigen::Vector3d Centre() const { return -R.transpose() * t; }
};

// Per-camera figures (pixels are undistorted pixels); empty optionals are JSON null.
struct CameraMetrics {
  std::optional<double> mean_px, std_px;  // of the inlier observations
  std::int64_t observations = 0;          // of this camera in the tracks
  std::int64_t inliers = 0;               // kept by the outlier filter
  std::int64_t track2_observations = 0;   // inliers whose point two registered cameras see
  std::int64_t view_score = 0;
  std::optional<std::string> failure;
  std::optional<double> rotation_sigma_deg;  // 1 sigma, worst direction
  std::optional<double> centre_sigma;        // in the calibration's unit
  bool weak = false;
};

// A plane besides the floor (coplanar model): normal . X = offset in the floor frame.
struct Plane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double offset = 0.0;
  std::int64_t points = 0;
};

using NamedText = std::pair<std::string, std::string>;
using PointRows = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

struct Calibration {
  std::vector<CameraPose> poses;                                  // registered cameras
  std::vector<NamedText> failed;                                  // camera -> reason
  std::vector<std::pair<std::string, CameraMetrics>> metrics;     // every camera
  PointRows points;                                               // floor frame
  std::vector<std::int64_t> point_ids;                            // one per point
  std::string unit = "arbitrary";                                 // or "m"
  std::string model = "coplanar";
  std::vector<std::string> registration_order;
  double floor_rms = 0.0;  // RMS distance of the floor's points to the floor
  std::vector<Plane> planes;
  // The poses' joint covariance from the final bundle adjustment (uncertainty.json holds
  // it; the three files do not); empty when not known.
  registration::PoseUncertainty uncertainty;

  // std::invalid_argument when points and ids differ in number or the unit is unknown.
  void Check() const;

  // nullptr when the camera is not registered.
  const CameraPose* PoseOf(const std::string& name) const;
  // Why the camera failed; empty when it did not.
  std::string FailureOf(const std::string& name) const;
  // "reference" (the first registered camera: the others' sigmas are relative to it),
  // "ok", "weak" (its rotation known worse than the registration's limit) or "failed".
  std::string Status(const std::string& name) const;
};

// The calibration of a registration: `cameras` and `point_ids` name the registration's
// cameras and points; `left_out` are cameras that failed before it (listed first among
// the failures, last among the metrics).
Calibration FromRegistration(const registration::RegistrationResult& result, const std::vector<std::string>& cameras,
                             const std::vector<std::int64_t>& point_ids, const std::vector<NamedText>& left_out,
                             const std::string& model);

// The same calibration with every length multiplied by `factor`, in metres.
// std::invalid_argument when the factor is not positive and finite.
Calibration Scaled(const Calibration& calibration, double factor);

// The per-camera summary both calibrate commands print with --json: per camera its
// name, whether registered, mean and std residual (px), inliers, observations, those of
// points two cameras see, view score, rotation and centre sigma, weak, failure, status.
std::string SummaryJson(const Calibration& calibration);

// The files' text.
std::string CameraPosesJson(const Calibration& calibration);
std::string MetricsJson(const Calibration& calibration);
std::string PointsPly(const Calibration& calibration);

// The camera poses of a camera_poses.json or of a simulation's truth.json (both write
// every camera as {R, t, center}), without a calibration's metrics and points: what
// `calibproj compare` compares.
struct CameraPoses {
  std::vector<CameraPose> poses;  // in the file's order
  std::vector<NamedText> failed;  // camera -> reason
  std::string unit = "arbitrary";  // or "m"
  std::vector<std::string> weak;   // cameras the file marks weakly determined
  std::string source;              // the file, for messages

  const CameraPose* PoseOf(const std::string& name) const;
};

// The poses of a camera_poses.json or a truth.json (told apart by its schema tag);
// InputError naming the file and the problem.
CameraPoses ReadCameraPoses(const std::filesystem::path& path);

// Files that a calibration writes; an existing one is only replaced with force.
extern const std::vector<std::string> kCalibrationFiles;

// The calibration a results folder holds (its three files); InputError naming the file
// and the problem, with the checks of the Python package's readers.
Calibration ReadCalibration(const std::filesystem::path& directory);

// Writes the three files into `directory` (created), each atomically.
void WriteCalibration(const std::filesystem::path& directory, const Calibration& calibration);

}  // namespace calibproj::formats
