#pragma once
// A capture: every camera of a site opened, recorded and ingested live while the
// projector plays the projection. Both front ends (`calibproj capture`,
// `calibproj-native capture`) run it and then calibrate or check from what arrived.
//
// Record(plan) runs, in order:
// 1. every camera's source opened in a thread of its own, recorded unchanged into the
//    recordings folder (<camera>.mkv) and ingested as its frames arrive (a camera whose
//    intrinsics file cannot be read fails alone, with the file's problem);
// 2. a wait until every camera delivers frames: one that does not within the site's
//    ready_s is stopped and reported, the others go on;
// 3. the projection played full screen on the projector's display (libmpv), with a
//    status line per camera now and then;
// 4. a wait until every camera's ingest has ended, which it does by itself once the end
//    light code is in: one still running end_s after the projection is stopped.
// `abort` set from any thread (Ctrl-C) stops the player and every source at once; every
// thread has ended when Record returns or throws.

#include <atomic>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "calibproj/capture/projector.h"
#include "calibproj/capture/site_file.h"
#include "calibproj/formats/detect_report.h"
#include "calibproj/ingest/camera_ingest.h"
#include "calibproj/ingest/sequence_description.h"

namespace calibproj::capture {

struct CapturePlan {
  Site site;                                  // cameras and sources, projector, timeouts
  std::filesystem::path sequence_file;        // for the capture log
  ingest::SequenceDescription sequence;       // what is projected
  std::filesystem::path video;                // ... and its video
  // Where each camera's frames get their intrinsics: the site's files, or (when set) the
  // camera's file in this folder (a stored calibration's intrinsics/, for a check).
  std::filesystem::path intrinsics_folder;
  ingest::IngestOptions options;              // every camera's; its exposure from the site
  std::filesystem::path recordings;           // receives <camera>.mkv (must exist)
  double status_interval_s = 2.0;             // a status line per camera this often; 0: none
};

// What one camera delivered.
struct Delivery {
  int frames = 0;                       // decoded
  std::optional<double> first_frame_s;  // since the capture started
  std::string recording;                // file name in the recordings folder
};

struct CaptureRun {
  std::vector<formats::CameraOutcome> cameras;  // in the site's order; `video` is the source
  std::vector<Delivery> delivered;              // the same order
  PresentationLog projection;
  double projection_started_s = 0.0;            // since the capture started
  double cameras_done_after_end_s = 0.0;
};

// The capture was stopped through `abort`.
class CaptureInterrupted : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A line for the user; `error` for failures (a camera left out, stopped).
using CaptureLogger = std::function<void(bool error, const std::string& line)>;

// Throws std::runtime_error when no camera delivers frames or the projector cannot play
// (the message names its display), CaptureInterrupted when `abort` was set.
CaptureRun Record(const CapturePlan& plan, const std::shared_ptr<std::atomic<bool>>& abort,
                  const CaptureLogger& log);

// capture.json (calibproj.capture/1): the site, the recordings folder, what each camera
// delivered, and when the projector showed each frame.
void WriteCaptureLog(const std::filesystem::path& path, const CapturePlan& plan, const CaptureRun& run);

}  // namespace calibproj::capture
