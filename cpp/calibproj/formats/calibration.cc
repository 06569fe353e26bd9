#include "calibproj/formats/calibration.h"

#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>

#include "calibproj/formats/files.h"

namespace calibproj::formats {

namespace fs = std::filesystem;
using ordered_json = nlohmann::ordered_json;

const std::vector<std::string> kCalibrationFiles = {"camera_poses.json", "metrics.json", "points.ply"};

namespace {

// A value, or null when there is none.
template <typename T>
ordered_json Optional(const std::optional<T>& value) {
  return value ? ordered_json(*value) : ordered_json(nullptr);
}

}  // namespace

void Calibration::Check() const {
  if (static_cast<size_t>(points.rows()) != point_ids.size()) {
    throw std::invalid_argument("calibration: " + std::to_string(points.rows()) + " points but " +
                                std::to_string(point_ids.size()) + " point ids");
  }
  if (unit != "arbitrary" && unit != "m") {
    throw std::invalid_argument("unit must be one of ('arbitrary', 'm'), got " + PythonRepr(unit));
  }
  uncertainty.Check();  // its cameras' poses are looked up where it is used (uncertainty::UncertaintyModel)
}

const CameraPose* Calibration::PoseOf(const std::string& name) const {
  for (const auto& pose : poses) {
    if (pose.name == name) return &pose;
  }
  return nullptr;
}

std::string Calibration::Status(const std::string& name) const {
  if (PoseOf(name) == nullptr) return "failed";
  if (!registration_order.empty() && registration_order.front() == name) return "reference";
  for (const auto& [camera, camera_metrics] : metrics) {
    if (camera == name) return camera_metrics.weak ? "weak" : "ok";
  }
  return "ok";
}

std::string SummaryJson(const Calibration& calibration) {
  nlohmann::ordered_json rows = nlohmann::ordered_json::array();
  for (const auto& [name, m] : calibration.metrics) {
    rows.push_back({{"camera", name},
                    {"registered", calibration.PoseOf(name) != nullptr},
                    {"mean_px", Optional(m.mean_px)},
                    {"std_px", Optional(m.std_px)},
                    {"inliers", m.inliers},
                    {"observations", m.observations},
                    {"track2", m.track2_observations},
                    {"view_score", m.view_score},
                    {"rotation_sigma_deg", Optional(m.rotation_sigma_deg)},
                    {"centre_sigma", Optional(m.centre_sigma)},
                    {"weak", m.weak},
                    {"failure", Optional(m.failure)},
                    {"status", calibration.Status(name)}});
  }
  return PythonJson(rows);
}

const CameraPose* CameraPoses::PoseOf(const std::string& name) const {
  for (const auto& pose : poses) {
    if (pose.name == name) return &pose;
  }
  return nullptr;
}

std::string Calibration::FailureOf(const std::string& name) const {
  for (const auto& [camera, reason] : failed) {
    if (camera == name) return reason;
  }
  return "";
}

namespace {

std::optional<double> Finite(double value) {
  return std::isfinite(value) ? std::optional<double>(value) : std::nullopt;
}

CameraMetrics MetricsOf(const registration::CameraResult& camera, const std::string& failure) {
  CameraMetrics m;
  if (camera.registered) {
    m.mean_px = camera.mean_px;
    m.std_px = camera.std_px;
    m.rotation_sigma_deg = Finite(camera.rotation_sigma_deg);
    m.centre_sigma = Finite(camera.centre_sigma);
    m.weak = camera.weak;
  }
  m.observations = camera.observations;
  m.inliers = camera.inliers;
  m.track2_observations = camera.track2_observations;
  m.view_score = camera.view_score;
  if (!failure.empty()) m.failure = failure;
  return m;
}

std::vector<Plane> PlanesOf(const registration::RegistrationResult& result) {
  std::vector<Plane> planes;
  for (int k = 0; k < result.planes.rows(); ++k) {
    Plane plane;
    plane.normal = result.planes.row(k).head<3>().transpose();
    plane.offset = result.planes(k, 3);
    for (int label : result.point_plane) plane.points += label == k + 1;
    planes.push_back(plane);
  }
  return planes;
}

}  // namespace

Calibration FromRegistration(const registration::RegistrationResult& result, const std::vector<std::string>& cameras,
                             const std::vector<std::int64_t>& point_ids, const std::vector<NamedText>& left_out,
                             const std::string& model) {
  Calibration calibration;
  calibration.model = model;
  calibration.failed = left_out;
  for (size_t c = 0; c < result.cameras.size(); ++c) {
    const auto& camera = result.cameras[c];
    if (camera.registered) {
      calibration.poses.push_back({cameras[c], camera.R, camera.t});
    } else if (!camera.failure.empty()) {
      calibration.failed.emplace_back(cameras[c], camera.failure);
    }
  }
  for (size_t c = 0; c < result.cameras.size(); ++c) {
    calibration.metrics.emplace_back(cameras[c], MetricsOf(result.cameras[c], calibration.FailureOf(cameras[c])));
  }
  for (const auto& [name, reason] : left_out) {
    CameraMetrics metrics;
    metrics.failure = reason;
    calibration.metrics.emplace_back(name, metrics);
  }
  calibration.points = result.points;
  for (int index : result.point_index) calibration.point_ids.push_back(point_ids[index]);
  for (int c : result.registration_order) calibration.registration_order.push_back(cameras[c]);
  calibration.floor_rms = result.floor_rms;
  calibration.planes = PlanesOf(result);
  calibration.uncertainty = result.uncertainty.Named(cameras);
  return calibration;
}

Calibration Scaled(const Calibration& calibration, double factor) {
  if (!(std::isfinite(factor) && factor > 0)) {
    throw std::invalid_argument("scale factor must be positive and finite, got " + PythonFloat(factor));
  }
  calibration.Check();
  Calibration out = calibration;
  for (auto& pose : out.poses) pose.t *= factor;
  for (auto& [name, metrics] : out.metrics) {
    if (metrics.centre_sigma) *metrics.centre_sigma *= factor;
  }
  out.points *= factor;
  out.unit = "m";
  out.floor_rms *= factor;
  for (auto& plane : out.planes) plane.offset *= factor;
  out.uncertainty = calibration.uncertainty.Scaled(factor);
  return out;
}

namespace {

ordered_json Vector(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

ordered_json Matrix(const Eigen::Matrix3d& R) {
  ordered_json rows = ordered_json::array();
  for (int i = 0; i < 3; ++i) rows.push_back(Vector(R.row(i).transpose()));
  return rows;
}

ordered_json Failures(const Calibration& calibration) {
  ordered_json failed = ordered_json::object();
  for (const auto& [name, reason] : calibration.failed) failed[name] = reason;
  return failed;
}

const CameraMetrics* FindMetrics(const Calibration& calibration, const std::string& name) {
  for (const auto& [camera, metrics] : calibration.metrics) {
    if (camera == name) return &metrics;
  }
  return nullptr;
}

}  // namespace

std::string CameraPosesJson(const Calibration& calibration) {
  ordered_json cameras = ordered_json::object();
  for (const auto& pose : calibration.poses) {
    ordered_json entry = {{"R", Matrix(pose.R)}, {"t", Vector(pose.t)}, {"center", Vector(pose.Centre())}};
    if (const CameraMetrics* m = FindMetrics(calibration, pose.name)) {
      entry["rotation_sigma_deg"] = Optional(m->rotation_sigma_deg);
      entry["centre_sigma"] = Optional(m->centre_sigma);
      entry["weak"] = m->weak;
    }
    cameras[pose.name] = entry;
  }
  const ordered_json body = {
      {"unit", calibration.unit}, {"frame", "floor"}, {"cameras", cameras}, {"failed", Failures(calibration)}};
  return DumpSchemaJson("camera_poses", 1, body);
}

std::string MetricsJson(const Calibration& calibration) {
  ordered_json planes = ordered_json::array();
  for (const auto& plane : calibration.planes) {
    planes.push_back({{"normal", Vector(plane.normal)}, {"offset", plane.offset}, {"points", plane.points}});
  }
  ordered_json cameras = ordered_json::object();
  for (const auto& [name, m] : calibration.metrics) {
    cameras[name] = {{"mean_px", Optional(m.mean_px)},
                     {"std_px", Optional(m.std_px)},
                     {"observations", m.observations},
                     {"inliers", m.inliers},
                     {"track2_observations", m.track2_observations},
                     {"view_score", m.view_score},
                     {"failure", Optional(m.failure)},
                     {"rotation_sigma_deg", Optional(m.rotation_sigma_deg)},
                     {"centre_sigma", Optional(m.centre_sigma)},
                     {"weak", m.weak}};
  }
  const ordered_json body = {{"unit", calibration.unit},
                             {"model", calibration.model},
                             {"registration_order", calibration.registration_order},
                             {"floor_rms", calibration.floor_rms},
                             {"planes", planes},
                             {"cameras", cameras}};
  return DumpSchemaJson("metrics", 1, body);
}

std::string PointsPly(const Calibration& calibration) {
  calibration.Check();
  std::ostringstream out;
  out << "ply\nformat ascii 1.0\ncomment schema calibproj.points/1\nelement vertex " << calibration.points.rows()
      << "\nproperty double x\nproperty double y\nproperty double z\nproperty int id\nend_header\n";
  char line[160];
  for (Eigen::Index p = 0; p < calibration.points.rows(); ++p) {
    std::snprintf(line, sizeof(line), "%.9g %.9g %.9g %lld\n", calibration.points(p, 0), calibration.points(p, 1),
                  calibration.points(p, 2), static_cast<long long>(calibration.point_ids[p]));
    out << line;
  }
  return out.str();
}

void WriteCalibration(const fs::path& directory, const Calibration& calibration) {
  calibration.Check();
  fs::create_directories(directory);
  AtomicWrite(directory / "camera_poses.json", CameraPosesJson(calibration));
  AtomicWrite(directory / "metrics.json", MetricsJson(calibration));
  AtomicWrite(directory / "points.ply", PointsPly(calibration));
}

}  // namespace calibproj::formats
