#pragma once
// The site file: the room named once (its cameras and their sources, the projector,
// the projection), read by `capture`. Schema calibproj.site/1, JSON:
//
//   {"schema": "calibproj.site/1",
//    "sequence": "projection/sequence.json",      the projection's sequence
//    "projection": "projection/projection.mp4",   optional; default: projection.mp4 beside it
//    "projector": {"display": ":0", "screen": 1, "video_output": "gpu,x11"},   all optional
//    "cameras": {
//      "far1": {"source": "rtsp://10.0.0.11/stream1",   URL, device or file
//               "intrinsics": "intrinsics/far1.json",
//               "format": "", "options": {"rtsp_transport": "tcp"},   optional: FFmpeg's
//               "exposure_s": 0.008,                                  optional: known exposure
//               "open_timeout_s": 10, "stall_timeout_s": 5}},         optional
//    "timeouts": {"ready_s": 20, "end_s": 10}}    optional
//
// Paths are relative to the site file's folder.

#include <filesystem>
#include <string>
#include <vector>

#include "calibproj/capture/projector.h"
#include "calibproj/formats/provenance.h"
#include "calibproj/video/video_reader.h"

namespace calibproj::capture {

struct SiteCamera {
  std::string name;
  std::string source;             // as FFmpeg opens it (a relative file path resolved)
  video::SourceOptions options;   // live; its record_path is the capture's to set
  std::filesystem::path intrinsics;
  double exposure_s = 0.0;        // 0: estimated from the light codes
};

struct Site {
  std::filesystem::path path;
  std::filesystem::path sequence;
  std::filesystem::path projection;
  ProjectorOptions projector;
  std::vector<SiteCamera> cameras;  // in name order
  // Every camera must deliver frames within ready_s of the capture's start; a camera
  // still ingesting end_s after the projection ended is stopped.
  double ready_s = 20.0;
  double end_s = 10.0;
};

// Reads and checks a site file: formats::InputError naming the file and the entry.
Site ReadSite(const std::filesystem::path& path);

// What provenance.json records as a capture's intrinsics: the files its site file names.
formats::ProvenanceInput SiteIntrinsicsProvenance();

}  // namespace calibproj::capture
