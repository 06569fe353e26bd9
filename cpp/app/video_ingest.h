#pragma once
// The ingest of a folder of camera videos on the command line, as `calibproj-native
// detect` and `calibproj-native calibrate VIDEOS_DIR` take it: the same flags (one per
// knob of the ingest's table, --workers, --exposure, --detector-option, --no-progress)
// and the same C++ ingest per camera (calibproj::ingest::IngestCamera), with the Python
// commands' messages.

#include <CLI/CLI.hpp>
#include <filesystem>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "calibproj/formats/camera_intrinsics.h"
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

  // Whether any ingest knob differs from its default (as the Python commands tell
  // ingest options given from none).
  bool AnyKnobChanged() const;
};

// The flags of the ingest on `command`; the ingest knobs named in `exclude` are left out
// (a knob another table of the command declares too).
void AddVideoIngestFlags(CLI::App* command, VideoIngestArguments* arguments,
                         const std::vector<std::string>& exclude = {});

// The videos of a folder, camera name (file stem) -> video, sorted by name; InputError
// for a missing folder, one without videos, or two videos of one camera.
std::map<std::string, std::filesystem::path> VideoPaths(const std::filesystem::path& folder);

// A camera's intrinsics by name, and where they come from (for its report); a problem
// raised fails that camera only.
using IntrinsicsLookup = std::function<formats::CameraIntrinsics(const std::string& name, std::string* source)>;

// Every camera's video in `videos` (<camera>.<video suffix>) through the ingest, with
// its intrinsics from `intrinsics_of`, `workers` cameras at a time; per camera in name
// order its outcome (a camera that fails is reported, the others go on). InputError for a
// missing folder, bad options, exposures or detector options.
std::vector<formats::CameraOutcome> IngestVideos(const std::string& videos, const IntrinsicsLookup& intrinsics_of,
                                                 const ingest::SequenceDescription& sequence,
                                                 const VideoIngestArguments& arguments);
// The same, each camera's intrinsics file read from the folder `intrinsics`.
std::vector<formats::CameraOutcome> IngestVideos(const std::string& videos, const std::string& intrinsics,
                                                 const ingest::SequenceDescription& sequence,
                                                 const VideoIngestArguments& arguments);

}  // namespace calibproj::app
