#include "calibproj/formats/detect_report.h"

#include <cmath>
#include <cstdio>

namespace calibproj::formats {

// Point id of an MSM: array * markers_per_array + marker (docs/conventions.md).
Tracks TracksOf(const std::vector<CameraOutcome>& outcomes, int markers_per_array) {
  std::vector<std::string> names;
  std::vector<int> camera;
  std::vector<std::int64_t> ids;
  std::vector<Eigen::Vector2d> xy;
  for (const CameraOutcome& outcome : outcomes) {
    const int index = static_cast<int>(names.size());
    names.push_back(outcome.name);
    if (!outcome.ok()) continue;  // kept without observations, so that calibration reports it
    for (const detect::MergedCentre& centre : outcome.result.centres) {
      camera.push_back(index);
      ids.push_back(static_cast<std::int64_t>(centre.array) * markers_per_array + centre.marker);
      xy.emplace_back(centre.centre.x, centre.centre.y);
    }
  }
  return MakeTracks(names, camera, ids, xy, markers_per_array);
}

namespace {

using nlohmann::ordered_json;

ordered_json SyncSummary(const sync::SyncResult& sync, double video_fps, double projector_fps) {
  const double nominal_rate = video_fps / projector_fps;
  ordered_json entry;
  entry["offset_frames"] = sync.map.offset;
  entry["offset_s"] = sync.map.offset / video_fps;
  entry["offset_uncertainty_frames"] = sync.offset_uncertainty;
  entry["rate"] = sync.map.rate;
  entry["camera_fps"] = sync.map.rate * projector_fps;
  entry["drift_ppm"] = (sync.map.rate / nominal_rate - 1.0) * 1e6;
  entry["exposure_frames"] = sync.map.exposure;
  entry["sharp"] = sync.sharp;
  entry["start_correlation"] = sync.start.correlation;
  entry["end_correlation"] = sync.end.correlation;
  entry["fit_rms"] = sync.rms;
  const bool readout = sync.readout.valid;
  entry["readout_s"] = readout ? ordered_json(sync.readout.readout / video_fps) : ordered_json(nullptr);
  entry["readout_sigma_s"] = readout ? ordered_json(sync.readout.readout_sigma / video_fps) : ordered_json(nullptr);
  return entry;
}

ordered_json ScalesSummary(const std::vector<ingest::ScaleStats>& stats, const std::vector<double>& scales) {
  ordered_json out = ordered_json::array();
  for (size_t i = 0; i < stats.size() && i < scales.size(); ++i) {
    const ingest::ScaleStats& s = stats[i];
    out.push_back({{"scale", scales[i]},
                   {"patterns", s.patterns},
                   {"detected_patterns", s.detected_patterns},
                   {"skipped_patterns", s.skipped_patterns},
                   {"searched", s.searched},
                   {"too_small", s.too_small},
                   {"outside", s.outside},
                   {"folded", s.folded},
                   {"detected", s.detected},
                   {"kept", s.kept},
                   {"spread_px", s.spread_count > 0 ? ordered_json(s.spread_px) : ordered_json(nullptr)},
                   {"spread_count", s.spread_count}});
  }
  return out;
}

}  // namespace

ordered_json CameraResultSummary(const ingest::CameraIngestResult& r, const ingest::SequenceDescription& sequence) {
  ordered_json entry;
  entry["sync"] = SyncSummary(r.sync, r.video.fps, sequence.fps);
  entry["video_info"] = {{"width", r.video.width},         {"height", r.video.height},
                         {"fps", r.video.fps},             {"declared_fps", r.video.declared_fps},
                         {"timed", r.video.timed},         {"frame_count", r.video.frame_count}};
  entry["frames"] = {{"decoded", r.frames_decoded},         {"converted", r.frames_converted},
                     {"detected", r.frames_detected},       {"dropped", r.timing.dropped},
                     {"duplicated", r.timing.duplicated},   {"untimed", r.timing.untimed},
                     {"largest_gap", r.timing.largest_gap}, {"jitter_ms", 1e3 * r.timing.jitter_rms_s}};
  entry["patterns"] = {{"whole_frame", r.patterns_whole_frame}, {"in_regions", r.patterns_in_regions},
                       {"dropped", r.patterns_dropped}, {"missing", r.patterns_missing}};
  entry["detections_rejected"] = r.detections_rejected;
  entry["markers_verified"] = r.markers_verified;
  entry["detections_inconsistent"] = r.detections_inconsistent;
  entry["consistency_problem"] =
      r.consistency_problem.empty() ? ordered_json(nullptr) : ordered_json(r.consistency_problem);
  entry["scales"] = ScalesSummary(r.scales, sequence.scales);
  entry["msms_kept"] = r.centres.size();
  const detect::ScaleDriftResult& drift = r.scale_drift;
  entry["scale_drift"] = {{"bandwidth", std::isfinite(drift.bandwidth) ? ordered_json(drift.bandwidth) : ordered_json("camera")},
                          {"msms", drift.msms}, {"corrected", drift.corrected}, {"rms_shift_px", drift.rms_shift_px}};
  entry["homography_rms_px"] = r.homography_valid ? ordered_json(r.homography_rms_px) : ordered_json(nullptr);
  entry["seconds"] = {{"total", r.seconds_total}, {"detection", r.seconds_detection}};
  return entry;
}

namespace {

ordered_json CameraSummary(const CameraOutcome& camera, const ingest::SequenceDescription& sequence) {
  ordered_json entry;
  entry["video"] = camera.video;
  entry["intrinsics"] = camera.intrinsics;
  entry["status"] = camera.ok() ? "ok" : "failed";
  if (!camera.ok()) {
    entry["error"] = camera.error;
    return entry;
  }
  const ordered_json summary = CameraResultSummary(camera.result, sequence);  // items() must not outlive it
  for (const auto& [key, value] : summary.items()) entry[key] = value;
  return entry;
}

std::string Format(const char* format, double a, double b = 0.0, double c = 0.0) {
  char text[64];
  std::snprintf(text, sizeof text, format, a, b, c);
  return text;
}

std::string CameraLines(const std::string& name, const ordered_json& camera) {
  if (camera.at("status") != "ok") return name + ": FAILED: " + camera.at("error").get<std::string>();
  const ordered_json& sync = camera.at("sync");
  const ordered_json& frames = camera.at("frames");
  std::string line = name + ": offset " + Format("%.4f", sync.at("offset_s").get<double>()) + " s (" +
                     Format("%.3f +- %.3f", sync.at("offset_frames").get<double>(),
                            sync.at("offset_uncertainty_frames").get<double>()) +
                     " frames), " + Format("%.4f", sync.at("camera_fps").get<double>()) + " fps (" +
                     Format("%+.0f", sync.at("drift_ppm").get<double>()) + " ppm), codes " +
                     Format("%.3f/%.3f", sync.at("start_correlation").get<double>(),
                            sync.at("end_correlation").get<double>()) +
                     "; frames " + std::to_string(frames.at("decoded").get<int>()) + " decoded (" +
                     std::to_string(frames.at("dropped").get<int>()) + " dropped, " +
                     std::to_string(frames.at("duplicated").get<int>()) + " duplicated), " +
                     std::to_string(frames.at("detected").get<int>()) + " detected; " +
                     std::to_string(camera.at("msms_kept").get<int>()) + " MSMs kept";
  if (camera.contains("scale_drift") && camera.at("scale_drift").value("corrected", 0) > 0) {
    line += Format(" (moved %.3f px rms for their scales' drift)",
                   camera.at("scale_drift").value("rms_shift_px", 0.0));
  }
  std::string per_scale;
  for (const auto& s : camera.at("scales")) {
    per_scale += (per_scale.empty() ? "" : ", ") + Format("%g", s.at("scale").get<double>()) + ": " +
                 std::to_string(s.at("detected").get<int>()) + "/" + std::to_string(s.at("searched").get<int>());
  }
  return line + "\n    markers found/searched per scale: " + per_scale;
}

}  // namespace

ordered_json DetectReport(const std::vector<CameraOutcome>& cameras, const std::string& sequence_source,
                          const ingest::SequenceDescription& sequence) {
  ordered_json report;
  report["sequence"] = sequence_source;
  report["markers"] = sequence.markers.spec;
  ordered_json entries = ordered_json::object();
  for (const CameraOutcome& camera : cameras) entries[camera.name] = CameraSummary(camera, sequence);
  report["cameras"] = entries;
  return report;
}

std::string FormatDetectReport(const ordered_json& report) {
  std::string text;
  for (const auto& [name, camera] : report.at("cameras").items()) {
    text += (text.empty() ? "" : "\n") + CameraLines(name, camera);
  }
  return text;
}

std::filesystem::path DetectReportPath(const std::filesystem::path& tracks) {
  const std::filesystem::path folder = tracks.has_parent_path() ? tracks.parent_path() : std::filesystem::path(".");
  const std::string stem = tracks.stem().string();
  return folder / (stem == "tracks" ? std::string("detect_report.json") : stem + ".detect_report.json");
}

}  // namespace calibproj::formats
