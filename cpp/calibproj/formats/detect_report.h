#pragma once
// detect_report.json (calibproj.detect_report/1) and the printed summary of the detect
// command, in the layout of the Python package (calibproj.ingest.videos.CameraIngest.summary).

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "calibproj/formats/intrinsics_file.h"
#include "calibproj/formats/tracks_file.h"
#include "calibproj/ingest/camera_ingest.h"

namespace calibproj::formats {

// What the ingest of one camera gave, or why it failed.
struct CameraOutcome {
  std::string name;        // the video's file stem
  std::string video;       // path of the video
  std::string intrinsics;  // path of the intrinsics file, or why there is none
  std::string error;       // empty when the camera succeeded
  ingest::CameraIngestResult result;

  bool ok() const { return error.empty(); }
};

// The tracks of the cameras' merged centres, every camera kept (a failed one without
// observations, so that calibration reports it).
Tracks TracksOf(const std::vector<CameraOutcome>& outcomes, int markers_per_array);

// A calibrated camera's entry of detect_report.json after video, intrinsics and status:
// sync, video_info, frames, patterns, detections, scales, MSMs kept, homography RMS,
// seconds (the Python package's report takes it from here too).
nlohmann::ordered_json CameraResultSummary(const ingest::CameraIngestResult& result,
                                           const ingest::SequenceDescription& sequence);

// The body of detect_report.json.
nlohmann::ordered_json DetectReport(const std::vector<CameraOutcome>& cameras, const std::string& sequence_source,
                                    const ingest::SequenceDescription& sequence);

// The report beside a tracks file: detect_report.json for tracks.json (a results
// folder's name), <stem>.detect_report.json for any other, so that detect runs into
// one folder keep a report each.
std::filesystem::path DetectReportPath(const std::filesystem::path& tracks);

// Per camera: sync, frames, markers per scale, MSMs kept (or the error).
std::string FormatDetectReport(const nlohmann::ordered_json& report);

}  // namespace calibproj::formats
