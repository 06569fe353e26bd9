#pragma once
// The ingest of a folder of camera videos on the command line, as `calibproj-native
// detect` and `calibproj-native calibrate VIDEOS_DIR` take it: the same flags (one per
// knob of the ingest's table, --workers, --exposure, --detector-option, --no-progress)
// and the same C++ ingest per camera (calibproj::ingest::IngestCamera), with the Python
// commands' messages.

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "calibproj/formats/detect_report.h"
#include "calibproj/ingest/camera_ingest.h"

namespace calibproj::app {

// Cameras processed at once, as in the Python command (each camera decodes with FFmpeg's
// own threads too).
constexpr int kDefaultDetectWorkers = 2;

struct VideoIngestArguments {
  int workers = kDefaultDetectWorkers;
  bool no_progress = false;
  std::vector<std::string> detector_options;  // NAME=VALUE, as calibproj.detect_markers takes them
  std::vector<std::string> exposures;         // CAMERA=SECONDS
  ingest::IngestOptions options;
  std::vector<const CLI::Option*> knob_flags;  // the ingest knobs' flags, once added

  // Whether any ingest knob was given on the command line.
  bool AnyKnobGiven() const {
    for (const CLI::Option* flag : knob_flags) {
      if (flag->count() > 0) return true;
    }
    return false;
  }
};

// The flags of the ingest on `command`; the ingest knobs named in `exclude` are left out
// (a knob another table of the command declares too).
void AddVideoIngestFlags(CLI::App* command, VideoIngestArguments* arguments,
                         const std::vector<std::string>& exclude = {});

// Every camera's video in `videos` (<camera>.<video suffix>) through the ingest, with
// its intrinsics file from `intrinsics`, `workers` cameras at a time; per camera in name
// order its outcome (a camera that fails is reported, the others go on). InputError for a
// missing folder, bad options, exposures or detector options.
std::vector<formats::CameraOutcome> IngestVideos(const std::string& videos, const std::string& intrinsics,
                                                 const ingest::SequenceDescription& sequence,
                                                 const VideoIngestArguments& arguments);

}  // namespace calibproj::app
