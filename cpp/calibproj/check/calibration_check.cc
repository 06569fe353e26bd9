#include "calibproj/check/calibration_check.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <nlohmann/json.hpp>
#include <set>
#include <stdexcept>

#include "calibproj/detect/lens.h"
#include "calibproj/formats/files.h"

namespace calibproj::check {

namespace {

constexpr double kVolumeHeightM = 2.0;
constexpr double kVolumeHeightShare = 0.7;
constexpr int kVolumeSamples = 9;  // per side of the floor
constexpr int kVolumeHeights = 5;
constexpr double kPi = 3.14159265358979323846;

using nlohmann::ordered_json;

// The camera's observations in `tracks` of points `calibration` holds: their stored
// positions and their pixels.
struct Held {
  Eigen::Matrix3Xd points;
  Eigen::Matrix2Xd observed;
  std::set<Eigen::Index> rows;  // the stored points observed
  int observations = 0;         // of the camera, of any point
};

// `only`: when given, the observations of those stored points only.
Held HeldObservations(const formats::Tracks* tracks, const std::string& name,
                      const std::map<std::int64_t, Eigen::Index>& stored, const formats::Calibration& calibration,
                      const std::set<Eigen::Index>* only = nullptr) {
  Held held;
  if (tracks == nullptr) return held;
  const auto camera = std::find(tracks->cameras.begin(), tracks->cameras.end(), name);
  if (camera == tracks->cameras.end()) return held;
  const int index = static_cast<int>(camera - tracks->cameras.begin());
  std::vector<Eigen::Index> rows, observations;
  for (Eigen::Index k = 0; k < tracks->camera_index.size(); ++k) {
    if (tracks->camera_index[k] != index) continue;
    ++held.observations;
    const auto found = stored.find(tracks->point_ids[tracks->point_index[k]]);
    if (found == stored.end() || (only != nullptr && only->count(found->second) == 0)) continue;
    rows.push_back(found->second);
    held.rows.insert(found->second);
    observations.push_back(k);
  }
  held.points.resize(3, static_cast<Eigen::Index>(rows.size()));
  held.observed.resize(2, static_cast<Eigen::Index>(rows.size()));
  for (std::size_t j = 0; j < rows.size(); ++j) {
    held.points.col(j) = calibration.points.row(rows[j]).transpose();
    held.observed.col(j) = tracks->xy.row(observations[j]).transpose();
  }
  return held;
}

const formats::CameraMetrics* MetricsOf(const formats::Calibration& calibration, const std::string& name) {
  for (const auto& [camera, metrics] : calibration.metrics) {
    if (camera == name) return &metrics;
  }
  return nullptr;
}

CameraVerdict Unknown(const std::string& reason, int points = 0, int inliers = 0) {
  return {"unknown", reason, points, inliers, std::nullopt};
}

CameraVerdict CheckOne(const std::string& name, const formats::CameraPose& pose, const CheckInputs& inputs,
                       const std::map<std::int64_t, Eigen::Index>& stored, const Eigen::Matrix3Xd& volume,
                       const CheckOptions& options) {
  const formats::Calibration& calibration = *inputs.calibration;
  const auto intrinsics = inputs.intrinsics->find(name);
  if (intrinsics == inputs.intrinsics->end()) {
    const auto why = inputs.unusable.find(name);
    return Unknown("no usable intrinsics: " +
                   (why != inputs.unusable.end() ? why->second : std::string("no intrinsics in the stored results")));
  }
  if (!intrinsics->second.has_resolution) {
    return Unknown("its intrinsics give no image size: where the working volume lies in its view is not known");
  }
  const formats::CameraMetrics* metrics = MetricsOf(calibration, name);
  if (metrics == nullptr) return Unknown("no metrics of it in the stored results");
  const Held held = HeldObservations(inputs.tracks, name, stored, calibration);
  if (held.points.cols() == 0) {
    const auto why = inputs.not_seen.find(name);
    const std::string seen = why != inputs.not_seen.end() ? why->second
                             : held.observations > 0
                                 ? std::to_string(held.observations) + " observations, none of a calibrated point"
                                 : "no marker";
    return {"not seen", seen + ": it keeps its stored pose", 0, 0, std::nullopt};
  }
  // The reference: the calibration's observations of the same points, when enough of
  // them: a fit to another part of the image would differ by the lens model's and the
  // floor's small errors there, which the new observations do not share.
  Held reference = HeldObservations(inputs.stored_tracks, name, stored, calibration, &held.rows);
  if (reference.points.cols() < options.min_points) {
    reference = HeldObservations(inputs.stored_tracks, name, stored, calibration);
  }
  const Eigen::Matrix3d& K = intrinsics->second.K;
  CameraCheckInput input;
  input.K = {K(0, 0), K(1, 1), K(0, 2), K(1, 2), K(0, 1)};
  input.dist = intrinsics->second.dist;
  input.R = pose.R;
  input.t = pose.t;
  input.rotation_sigma = metrics->rotation_sigma_deg.value_or(0.0) * kPi / 180.0;
  input.centre_sigma = metrics->centre_sigma.value_or(0.0);
  input.points = held.points;
  input.observed = held.observed;
  input.reference_points = reference.points;
  input.reference_observed = reference.observed;
  input.volume = volume;
  input.width = intrinsics->second.width;
  input.height = intrinsics->second.height;
  CameraCheck result;
  try {
    result = CheckCamera(input, options);
  } catch (const std::invalid_argument& error) {  // this camera's stored figures: the others are tested
    return Unknown(std::string("not testable: ") + error.what());
  }
  if (result.status == Status::kUnknown) return Unknown(result.reason, result.points, result.inliers);
  return {StatusName(result.status), result.reason, result.points, result.inliers, result};
}

std::pair<bool, std::string> Majority(const CalibrationCheck& check) {
  const std::vector<std::string> tested = check.Tested();
  const std::size_t changed = check.Changed().size();
  const std::size_t agree = tested.size() - changed;
  if (tested.size() < 2) {
    return {false, std::to_string(tested.size()) +
                       " camera(s) tested: too few to tell whether the stored calibration holds (see why the "
                       "others were not)"};
  }
  if (2 * agree <= tested.size()) {
    return {false, "only " + std::to_string(agree) + " of the " + std::to_string(tested.size()) +
                       " cameras tested agree with the stored calibration: the floor, the projector or most cameras "
                       "changed; run a full calibration (calibproj calibrate), nothing was repaired"};
  }
  std::string message = std::to_string(agree) + " of " + std::to_string(tested.size()) + " cameras unchanged";
  if (changed > 0) message += ", " + std::to_string(changed) + " changed";
  return {true, message};
}

// The larger of two sigmas, either of which may be unknown (or 0: not estimated).
std::optional<double> LargerSigma(std::optional<double> stored, double fitted) {
  std::optional<double> larger = stored && *stored != 0.0 ? stored : std::nullopt;
  if (fitted != 0.0 && (!larger || fitted > *larger)) larger = fitted;
  return larger;
}

// SO(3)'s left Jacobian: Exp(w + dw) = Exp(J(w) dw) Exp(w) to first order.
Eigen::Matrix3d LeftJacobian(const Eigen::Vector3d& w) {
  const double angle = w.norm();
  Eigen::Matrix3d W;
  W << 0.0, -w.z(), w.y(), w.z(), 0.0, -w.x(), -w.y(), w.x(), 0.0;
  if (angle < 1e-8) return Eigen::Matrix3d::Identity() + 0.5 * W;
  return Eigen::Matrix3d::Identity() + (1.0 - std::cos(angle)) / (angle * angle) * W +
         (angle - std::sin(angle)) / (angle * angle * angle) * W * W;
}

// The stored joint covariance with the changed cameras as they are now. A repaired
// camera was fitted to the held points, which the other cameras placed: it keeps its
// stored covariance and its cross terms with them (it stands to those points as
// before) and gains its fit's, from the new observations. A re-zoomed camera's focal
// length gets a lens block (its variance and its cross terms with the pose) when it has
// none. Empty when nothing is stored or a changed camera is not in it.
registration::PoseUncertainty RepairedUncertainty(const formats::Calibration& stored, const CalibrationCheck& check,
                                                  const std::map<std::string, formats::CameraIntrinsics>& before) {
  registration::PoseUncertainty out = stored.uncertainty;
  if (out.empty()) return out;
  const int C = static_cast<int>(out.cameras.size());
  constexpr int L = registration::PoseUncertainty::kLensSize;
  std::vector<std::string> changed = check.Changed();
  for (const std::string& name : changed) {
    if (out.IndexOf(name) < 0) return {};
  }
  // New lens blocks for re-zoomed cameras without one.
  if (out.lens_block.empty()) out.lens_block.assign(C, -1);
  int lenses = out.num_lenses();
  for (const std::string& name : changed) {
    const CameraCheck& fit = *check.Find(name)->figures;
    if (fit.fit_covariance(6, 6) > 0.0 && out.lens_block[out.IndexOf(name)] < 0) out.lens_block[out.IndexOf(name)] = lenses++;
  }
  const int size = 6 * C + L * lenses;
  Eigen::MatrixXd covariance = Eigen::MatrixXd::Zero(size, size);
  covariance.topLeftCorner(stored.uncertainty.covariance.rows(), stored.uncertainty.covariance.cols()) =
      stored.uncertainty.covariance;
  for (const std::string& name : changed) {
    const int k = out.IndexOf(name);
    const CameraCheck& fit = *check.Find(name)->figures;
    const formats::CameraPose& was = *stored.PoseOf(name);
    // (w, centre, focal scale) -> (dtheta, dt, df): R = Exp(dtheta) R, t = -R C, f = s f_stored.
    const Eigen::AngleAxisd turn(fit.R * was.R.transpose());
    const Eigen::Matrix3d J = LeftJacobian(turn.angle() * turn.axis());
    Eigen::Matrix3d t_cross;
    t_cross << 0.0, -fit.t.z(), fit.t.y(), fit.t.z(), 0.0, -fit.t.x(), -fit.t.y(), fit.t.x(), 0.0;
    Eigen::Matrix<double, 7, 7> T = Eigen::Matrix<double, 7, 7>::Zero();
    T.block<3, 3>(0, 0) = J;
    T.block<3, 3>(3, 0) = -t_cross * J;
    T.block<3, 3>(3, 3) = -fit.R;
    T(6, 6) = before.at(name).K(0, 0);
    const Eigen::Matrix<double, 7, 7> mapped = T * fit.fit_covariance * T.transpose();
    const Eigen::Matrix<double, 7, 7> added = 0.5 * (mapped + mapped.transpose());
    std::vector<int> rows;
    for (int i = 0; i < 6; ++i) rows.push_back(6 * k + i);
    rows.push_back(out.lens_block[k] >= 0 ? 6 * C + L * out.lens_block[k] : -1);  // f, first of its lens
    for (int a = 0; a < 7; ++a) {
      for (int b = 0; b < 7; ++b) {
        if (rows[a] >= 0 && rows[b] >= 0) covariance(rows[a], rows[b]) += added(a, b);
      }
    }
    if (fit.noise_px > 0.0) out.noise_px[k] = fit.noise_px;
  }
  out.covariance = covariance;
  if (std::count(out.lens_block.begin(), out.lens_block.end(), -1) == C) out.lens_block.clear();
  try {
    out.Check();
  } catch (const std::invalid_argument&) {
    return {};  // a stored file readable but absurd (values near overflow): no uncertainty rather than a wrong one
  }
  return out;
}

// `stored` with the observations of `cameras` replaced by theirs in `now`.
formats::Tracks WithObservationsOf(const formats::Tracks& stored, const formats::Tracks& now,
                                   const std::vector<std::string>& cameras) {
  std::vector<int> camera;
  std::vector<std::int64_t> ids;
  std::vector<Eigen::Vector2d> xy;
  for (std::size_t c = 0; c < stored.cameras.size(); ++c) {
    const std::string& name = stored.cameras[c];
    const bool changed = std::find(cameras.begin(), cameras.end(), name) != cameras.end();
    const formats::Tracks& source = changed ? now : stored;
    const auto found = std::find(source.cameras.begin(), source.cameras.end(), name);
    if (found == source.cameras.end()) continue;
    const int index = static_cast<int>(found - source.cameras.begin());
    for (Eigen::Index k = 0; k < source.camera_index.size(); ++k) {
      if (source.camera_index[k] != index) continue;
      camera.push_back(static_cast<int>(c));
      ids.push_back(source.point_ids[source.point_index[k]]);
      xy.push_back(source.xy.row(k).transpose());
    }
  }
  return formats::MakeTracks(stored.cameras, camera, ids, xy, stored.markers_per_array);
}

// `tracks` with the camera's pixels (undistorted with K `before`) undistorted with K
// `after` instead: a re-zoomed camera's observations as its new intrinsics give them.
formats::Tracks Reundistorted(formats::Tracks tracks, const std::string& name, const Eigen::Matrix3d& before,
                              const Eigen::Matrix3d& after, const std::vector<double>& dist) {
  const auto camera = std::find(tracks.cameras.begin(), tracks.cameras.end(), name);
  if (camera == tracks.cameras.end()) return tracks;
  const int index = static_cast<int>(camera - tracks.cameras.begin());
  std::vector<Eigen::Index> rows;
  std::vector<cv::Point2d> pixels;
  for (Eigen::Index k = 0; k < tracks.camera_index.size(); ++k) {
    if (tracks.camera_index[k] != index) continue;
    rows.push_back(k);
    pixels.emplace_back(tracks.xy(k, 0), tracks.xy(k, 1));
  }
  const auto lens = [&](const Eigen::Matrix3d& K) {
    formats::CameraIntrinsics model;
    model.K = K;
    model.dist = dist;
    return model;
  };
  const std::vector<cv::Point2d> moved =
      detect::UndistortPixels(lens(after), detect::DistortPixels(lens(before), pixels));
  for (std::size_t j = 0; j < rows.size(); ++j) tracks.xy.row(rows[j]) << moved[j].x, moved[j].y;
  return tracks;
}

// Python's round(value, 6): correctly rounded to six decimals.
double Rounded6(double value) {
  char text[64];
  std::snprintf(text, sizeof(text), "%.6f", value);
  return std::strtod(text, nullptr);
}

ordered_json Figure(const std::optional<CameraCheck>& figures, double CameraCheck::*field) {
  return figures ? ordered_json(Rounded6((*figures).*field)) : ordered_json(nullptr);
}

}  // namespace

bool CameraVerdict::Tested() const { return status == "unchanged" || Changed(); }
bool CameraVerdict::Changed() const { return status == "moved" || status == "rezoomed"; }

std::vector<std::string> CalibrationCheck::Tested() const {
  std::vector<std::string> names;
  for (const auto& [name, verdict] : cameras) {
    if (verdict.Tested()) names.push_back(name);
  }
  return names;
}

std::vector<std::string> CalibrationCheck::Changed() const {
  std::vector<std::string> names;
  for (const auto& [name, verdict] : cameras) {
    if (verdict.Changed()) names.push_back(name);
  }
  return names;
}

const CameraVerdict* CalibrationCheck::Find(const std::string& name) const {
  for (const auto& [camera, verdict] : cameras) {
    if (camera == name) return &verdict;
  }
  return nullptr;
}

Eigen::Matrix3Xd WorkingVolume(const formats::Calibration& calibration) {
  const Eigen::Vector2d low = calibration.points.leftCols<2>().colwise().minCoeff().transpose();
  const Eigen::Vector2d high = calibration.points.leftCols<2>().colwise().maxCoeff().transpose();
  double top = kVolumeHeightM;
  if (calibration.unit != "m") {
    double highest = -std::numeric_limits<double>::infinity();
    for (const auto& pose : calibration.poses) highest = std::max(highest, pose.Centre().z());
    top = kVolumeHeightShare * highest;
  }
  const Eigen::VectorXd xs = Eigen::VectorXd::LinSpaced(kVolumeSamples, low.x(), high.x());
  const Eigen::VectorXd ys = Eigen::VectorXd::LinSpaced(kVolumeSamples, low.y(), high.y());
  const Eigen::VectorXd zs = Eigen::VectorXd::LinSpaced(kVolumeHeights, 0.0, top);
  Eigen::Matrix3Xd volume(3, kVolumeSamples * kVolumeSamples * kVolumeHeights);
  Eigen::Index k = 0;
  for (Eigen::Index i = 0; i < xs.size(); ++i) {
    for (Eigen::Index j = 0; j < ys.size(); ++j) {
      for (Eigen::Index h = 0; h < zs.size(); ++h) volume.col(k++) = Eigen::Vector3d(xs[i], ys[j], zs[h]);
    }
  }
  return volume;
}

// std::invalid_argument naming the first inconsistent input.
static void CheckInputsAgree(const CheckInputs& inputs) {
  inputs.calibration->Check();
  inputs.tracks->Check();
  if (inputs.stored_tracks != nullptr) inputs.stored_tracks->Check();
}

CalibrationCheck CheckCalibration(const CheckInputs& inputs, const CheckOptions& options) {
  CheckInputsAgree(inputs);
  const formats::Calibration& calibration = *inputs.calibration;
  if (calibration.poses.empty() || calibration.points.rows() == 0) {
    throw std::invalid_argument(
        "the stored calibration has no registered camera or no point: nothing to check against");
  }
  std::map<std::int64_t, Eigen::Index> stored;
  for (Eigen::Index p = 0; p < static_cast<Eigen::Index>(calibration.point_ids.size()); ++p) {
    stored.emplace(calibration.point_ids[p], p);
  }
  const auto& ids = inputs.tracks->point_ids;
  if (std::none_of(ids.begin(), ids.end(), [&](std::int64_t id) { return stored.count(id) > 0; })) {
    throw std::invalid_argument(
        "the check projection shows none of the calibrated points: make it with `calibproj generate --check "
        "RESULTS` from the sequence RESULTS were calibrated from");
  }
  const Eigen::Matrix3Xd volume = WorkingVolume(calibration);
  CalibrationCheck check;
  check.unit = calibration.unit;
  for (const auto& pose : calibration.poses) {
    check.cameras.emplace_back(pose.name, CheckOne(pose.name, pose, inputs, stored, volume, options));
  }
  for (const auto& [name, reason] : calibration.failed) {
    check.cameras.emplace_back(name, Unknown("not in the stored calibration (" + reason + ")"));
  }
  std::tie(check.trusted, check.message) = Majority(check);
  return check;
}

Repair Repaired(const CheckInputs& inputs, const CalibrationCheck& check, double weak_rotation_sigma_deg) {
  if (!check.trusted) throw std::invalid_argument(check.message);
  CheckInputsAgree(inputs);
  if (inputs.stored_tracks == nullptr) throw std::invalid_argument("the repair needs the stored tracks");
  Repair repair{*inputs.calibration, *inputs.intrinsics, {}};
  const std::vector<std::string> changed = check.Changed();
  for (const std::string& name : changed) {
    const CameraVerdict* verdict = check.Find(name);
    if (!verdict->figures || !repair.intrinsics.count(name) || !repair.calibration.PoseOf(name)) {
      throw std::invalid_argument("camera " + name + " of the check is not in this calibration");
    }
    const CameraCheck& figures = *verdict->figures;
    for (auto& pose : repair.calibration.poses) {
      if (pose.name == name) pose.R = figures.R, pose.t = figures.t;
    }
    if (figures.focal_scale != 1.0) repair.intrinsics.at(name).K.topLeftCorner<2, 2>() *= figures.focal_scale;
    for (auto& [camera, metrics] : repair.calibration.metrics) {
      if (camera != name) continue;
      // Fitted to points the other cameras placed, it is known relative to them at
      // best as well as before: the stored sigma, or the fit's when larger.
      metrics.mean_px = figures.rms_after_px;
      metrics.std_px = figures.noise_px;
      metrics.observations = figures.points;
      metrics.inliers = metrics.track2_observations = figures.inliers;
      metrics.rotation_sigma_deg = LargerSigma(metrics.rotation_sigma_deg, figures.rotation_sigma_deg);
      metrics.centre_sigma = LargerSigma(metrics.centre_sigma, figures.centre_sigma);
      metrics.weak = metrics.weak ||
                     (metrics.rotation_sigma_deg && *metrics.rotation_sigma_deg > weak_rotation_sigma_deg);
    }
  }
  // A re-zoomed camera's pixels, undistorted with its stored focal length, are made
  // again with its new one (the intrinsics written beside them).
  formats::Tracks now = *inputs.tracks;
  for (const std::string& name : changed) {
    const formats::CameraIntrinsics& stored = inputs.intrinsics->at(name);
    if (check.Find(name)->figures->focal_scale != 1.0) {
      now = Reundistorted(std::move(now), name, stored.K, repair.intrinsics.at(name).K, stored.dist);
    }
  }
  repair.tracks = WithObservationsOf(*inputs.stored_tracks, now, changed);
  repair.calibration.uncertainty = RepairedUncertainty(*inputs.calibration, check, *inputs.intrinsics);
  return repair;
}

std::string CheckJson(const CalibrationCheck& check) {
  ordered_json cameras = ordered_json::object();
  for (const auto& [name, verdict] : check.cameras) {
    const auto& f = verdict.figures;
    cameras[name] = {{"status", verdict.status},
                     {"reason", verdict.reason},
                     {"points", verdict.points},
                     {"inliers", verdict.inliers},
                     {"noise_px", Figure(f, &CameraCheck::noise_px)},
                     {"rms_before_px", Figure(f, &CameraCheck::rms_before_px)},
                     {"rms_after_px", Figure(f, &CameraCheck::rms_after_px)},
                     {"rotation_change_deg", Figure(f, &CameraCheck::rotation_change_deg)},
                     {"rotation_sigma_deg", Figure(f, &CameraCheck::rotation_sigma_deg)},
                     {"centre_change", Figure(f, &CameraCheck::centre_change)},
                     {"centre_sigma", Figure(f, &CameraCheck::centre_sigma)},
                     {"focal_change", Figure(f, &CameraCheck::focal_change)},
                     {"focal_sigma", Figure(f, &CameraCheck::focal_sigma)},
                     {"volume_shift_px", Figure(f, &CameraCheck::volume_shift_px)},
                     {"volume_shift_sigma_px", Figure(f, &CameraCheck::volume_shift_sigma_px)},
                     {"focal_scale", f ? Rounded6(f->focal_scale) : 1.0}};
  }
  const ordered_json body = {
      {"unit", check.unit}, {"trusted", check.trusted}, {"message", check.message}, {"cameras", cameras}};
  return formats::DumpSchemaJson("check", 1, body);
}

std::string CheckTable(const CalibrationCheck& check) {
  const bool metric = check.unit == "m";
  const std::string unit = metric ? "mm" : check.unit;
  const double scale = metric ? 1000.0 : 1.0;
  char line[512];
  std::snprintf(line, sizeof(line), "%-12s%-11s%16s%18s%9s%11s%22s", "camera", "status", "rotation deg",
                ("centre " + unit).c_str(), "focal %", "volume px", "rms px before/after");
  const std::string header = line;
  std::string table = header + "\n" + std::string(header.size(), '-');
  for (const auto& [name, verdict] : check.cameras) {
    if (!verdict.figures) {
      std::snprintf(line, sizeof(line), "%-12s%-11s", name.c_str(), verdict.status.c_str());
      table += "\n" + std::string(line) + verdict.reason;
      continue;
    }
    const CameraCheck& f = *verdict.figures;
    std::snprintf(line, sizeof(line), "%-12s%-11s%8.3f +-%6.3f%9.2f +-%6.2f%9.2f%11.2f%13.3f / %.3f", name.c_str(),
                  verdict.status.c_str(), f.rotation_change_deg, f.rotation_sigma_deg, f.centre_change * scale,
                  f.centre_sigma * scale, 100.0 * f.focal_change, f.volume_shift_px, f.rms_before_px,
                  f.rms_after_px);
    table += "\n" + std::string(line);
  }
  return table;
}

int CheckExitStatus(const CalibrationCheck& check, bool repaired) {
  // Too few cameras tested says nothing against the calibration: not confirmed.
  if (!check.trusted) return check.Tested().size() >= 2 ? kExitUntrusted : kExitNotConfirmed;
  for (const auto& [name, verdict] : check.cameras) {
    if (verdict.status == "not seen" || verdict.status == "unknown") return kExitNotConfirmed;
  }
  return !check.Changed().empty() && !repaired ? kExitNotConfirmed : 0;
}

}  // namespace calibproj::check
