#include "calibproj/formats/results_file.h"

#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <sstream>

#include "calibproj/formats/files.h"

namespace calibproj::formats {

namespace fs = std::filesystem;
using ordered_json = nlohmann::ordered_json;

const std::vector<std::string> kResultFiles = {"camera_poses.json", "metrics.json", "points.ply"};

namespace {

ordered_json Matrix(const Eigen::Matrix3d& R) {
  ordered_json rows = ordered_json::array();
  for (int i = 0; i < 3; ++i) rows.push_back({R(i, 0), R(i, 1), R(i, 2)});
  return rows;
}

ordered_json Vector(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

// Failure reasons by name: the cameras left out first, then registration failures.
ordered_json Failures(const registration::RegistrationResult& result, const ResultFiles& names) {
  ordered_json failed = ordered_json::object();
  for (const auto& [name, reason] : names.left_out) failed[name] = reason;
  for (size_t c = 0; c < result.cameras.size(); ++c) {
    if (!result.cameras[c].registered && !result.cameras[c].failure.empty()) {
      failed[names.cameras[c]] = result.cameras[c].failure;
    }
  }
  return failed;
}

std::string CameraPosesJson(const registration::RegistrationResult& result, const ResultFiles& names) {
  ordered_json cameras = ordered_json::object();
  for (size_t c = 0; c < result.cameras.size(); ++c) {
    const auto& camera = result.cameras[c];
    if (!camera.registered) continue;
    const auto finite = [](double value) { return std::isfinite(value) ? ordered_json(value) : ordered_json(nullptr); };
    cameras[names.cameras[c]] = {{"R", Matrix(camera.R)},
                                 {"t", Vector(camera.t)},
                                 {"center", Vector(-camera.R.transpose() * camera.t)},
                                 {"rotation_sigma_deg", finite(camera.rotation_sigma_deg)},
                                 {"centre_sigma", finite(camera.centre_sigma)},
                                 {"weak", camera.weak}};
  }
  ordered_json body = {{"unit", "arbitrary"}, {"frame", "floor"}, {"cameras", cameras},
                       {"failed", Failures(result, names)}};
  return DumpSchemaJson("camera_poses", 1, body);
}

std::string MetricsJson(const registration::RegistrationResult& result, const ResultFiles& names) {
  const ordered_json failed = Failures(result, names);
  ordered_json cameras = ordered_json::object();
  for (size_t c = 0; c < result.cameras.size(); ++c) {
    const auto& camera = result.cameras[c];
    const std::string& name = names.cameras[c];
    ordered_json entry;
    entry["mean_px"] = camera.registered ? ordered_json(camera.mean_px) : ordered_json(nullptr);
    entry["std_px"] = camera.registered ? ordered_json(camera.std_px) : ordered_json(nullptr);
    entry["observations"] = camera.observations;
    entry["inliers"] = camera.inliers;
    entry["track2_observations"] = camera.track2_observations;
    entry["view_score"] = camera.view_score;
    entry["failure"] = failed.contains(name) ? failed[name] : ordered_json(nullptr);
    const auto finite = [&](double value) {
      return camera.registered && std::isfinite(value) ? ordered_json(value) : ordered_json(nullptr);
    };
    entry["rotation_sigma_deg"] = finite(camera.rotation_sigma_deg);
    entry["centre_sigma"] = finite(camera.centre_sigma);
    entry["weak"] = camera.registered && camera.weak;
    cameras[name] = entry;
  }
  for (const auto& [name, reason] : names.left_out) {
    cameras[name] = {{"mean_px", nullptr},    {"std_px", nullptr},
                     {"observations", 0},     {"inliers", 0},
                     {"track2_observations", 0}, {"view_score", 0},
                     {"failure", reason},     {"rotation_sigma_deg", nullptr},
                     {"centre_sigma", nullptr}, {"weak", false}};
  }
  ordered_json order = ordered_json::array();
  for (int c : result.registration_order) order.push_back(names.cameras[c]);
  ordered_json body = {{"unit", "arbitrary"}, {"model", names.model}, {"registration_order", order},
                       {"floor_rms", result.floor_rms}, {"cameras", cameras}};
  return DumpSchemaJson("metrics", 1, body);
}

std::string PointsPly(const registration::RegistrationResult& result, const ResultFiles& names) {
  std::ostringstream out;
  out << "ply\nformat ascii 1.0\ncomment schema calibproj.points/1\nelement vertex " << result.points.rows()
      << "\nproperty double x\nproperty double y\nproperty double z\nproperty int id\nend_header\n";
  char line[160];
  for (int p = 0; p < result.points.rows(); ++p) {
    std::snprintf(line, sizeof(line), "%.9g %.9g %.9g %lld\n", result.points(p, 0), result.points(p, 1),
                  result.points(p, 2), static_cast<long long>(names.point_ids[result.point_index[p]]));
    out << line;
  }
  return out.str();
}

}  // namespace

void WriteResults(const fs::path& out, const registration::RegistrationResult& result, const ResultFiles& names) {
  fs::create_directories(out);
  AtomicWrite(out / "camera_poses.json", CameraPosesJson(result, names));
  AtomicWrite(out / "metrics.json", MetricsJson(result, names));
  AtomicWrite(out / "points.ply", PointsPly(result, names));
}

}  // namespace calibproj::formats
