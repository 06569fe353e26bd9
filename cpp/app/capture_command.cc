#include "capture_command.h"

#include <chrono>
#include <condition_variable>
#include <ctime>
#include <filesystem>
#include <iostream>
#include <mutex>
#include <optional>

#include "calibproj/capture/session.h"
#include "calibproj/capture/site_file.h"
#include "calibproj/formats/detect_report.h"
#include "calibproj/formats/export.h"
#include "calibproj/formats/files.h"
#include "calibproj/formats/sequence_file.h"
#include "calibrate_command.h"
#include "check_command.h"
#include "table_flags.h"

namespace calibproj::app {

using formats::OutputBusyError;
using formats::OutputFolder;
using formats::PathlibPath;
namespace fs = std::filesystem;
using formats::InputError;

std::shared_ptr<CaptureArguments> AddCaptureCommand(CLI::App& app, CLI::App** command) {
  auto args = std::make_shared<CaptureArguments>();
  CLI::App* cmd = app.add_subcommand(
      "capture",
      "Run the room from its site file: every camera recorded and ingested live while the projector plays the "
      "projection, then calibrated into --out (what calibrate writes, plus recordings/ with capture.json), or with "
      "--check RESULTS the stored calibration checked and repaired as check does. A camera that cannot be opened, "
      "stalls or drops out is reported by name and the others go on; the recordings are kept whatever happens.");
  cmd->add_option("site", args->site, "the site file (calibproj.site/1: cameras, projector, projection)")
      ->required()
      ->type_name("SITE");
  SharedFlag(cmd, "--out", args->out);
  SharedFlag(cmd, "--recordings", args->recordings);
  SharedFlag(cmd, "--check", args->check);
  SharedFlag(cmd, "--sequence", args->sequence);
  SharedFlag(cmd, "--projection", args->projection);
  SharedFlag(cmd, "--scale", args->scale);
  SharedFlag(cmd, "--force", args->force);
  SharedFlag(cmd, "--export", args->exports);
  SharedFlag(cmd, "--no-progress", args->no_progress);
  SharedFlag(cmd, "--json", args->json);
  registration::VisitRegistrationOptions(args->options, TableFlags(cmd, "registration options"));
  AddRefinementFlags(cmd, &args->refine_intrinsics, &args->self_calibration);
  *command = cmd;
  return args;
}

namespace {

// What is projected: the site file's sequence and video, or those given.
struct Projection {
  fs::path sequence_file;
  fs::path video;
  ingest::SequenceDescription sequence;
};

Projection Projected(const capture::Site& site, const CaptureArguments& arguments) {
  Projection projection;
  if (arguments.sequence.empty()) {
    projection.sequence_file = site.sequence;
    projection.video = site.projection;
  } else {
    projection.sequence_file = arguments.sequence;
    projection.video = arguments.projection.empty() ? projection.sequence_file.parent_path() / "projection.mp4"
                                                    : fs::path(arguments.projection);
  }
  if (!fs::is_regular_file(projection.video)) {
    throw InputError(site.path.string() + ": projection " + projection.video.string() +
                     ": no such file (calibproj generate writes it)");
  }
  projection.sequence = formats::ReadSequence(projection.sequence_file.string());
  return projection;
}

// The recordings folder: the one given, else <beside>-recordings-<time> beside it.
fs::path RecordingsFolder(const std::string& given, const fs::path& beside) {
  if (!given.empty()) return given;
  const std::time_t now = std::time(nullptr);
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", std::localtime(&now));
  const fs::path folder = beside.has_filename() ? beside : beside.parent_path();
  return folder.parent_path() / (folder.filename().string() + "-recordings-" + stamp);
}

// A capture run in the calling thread; an interruption (Ctrl-C, SIGTERM) stops the player
// and every camera and waits for them, so that the recordings are complete, then says
// where they are kept before the process exits.
class CaptureRunner {
 public:
  CaptureRunner(Interrupts& interrupts, fs::path recordings) : interrupts_(interrupts), recordings_(recordings) {
    interrupts_.SetStopper([this] { StopAndWait(); });
  }
  ~CaptureRunner() { interrupts_.SetStopper({}); }

  capture::CaptureRun Record(const capture::CapturePlan& plan, bool progress) {
    const capture::CaptureLogger log = [](bool, const std::string& line) {
      static std::mutex printing;
      const std::lock_guard<std::mutex> held(printing);
      std::cerr << line << "\n";
    };
    struct Done {
      CaptureRunner& runner;
      ~Done() { runner.Finished(); }
    } done{*this};
    capture::CapturePlan own = plan;
    if (!progress) own.status_interval_s = 0.0;
    return capture::Record(own, abort_, log);
  }

 private:
  void Finished() {
    const std::lock_guard<std::mutex> held(mutex_);
    finished_ = true;
    ended_.notify_all();
  }

  void StopAndWait() {
    abort_->store(true);
    std::unique_lock<std::mutex> held(mutex_);
    ended_.wait_for(held, std::chrono::seconds(15), [this] { return finished_; });
    std::cerr << "capture interrupted; the recordings are kept in " << recordings_.string() << "\n";
  }

  Interrupts& interrupts_;
  fs::path recordings_;
  std::shared_ptr<std::atomic<bool>> abort_ = std::make_shared<std::atomic<bool>>(false);
  std::mutex mutex_;
  std::condition_variable ended_;
  bool finished_ = false;
};

// The intrinsics the site names, read; a camera whose file cannot be read has failed in
// the ingest already, with the file's problem as its reason.
formats::IntrinsicsDir SiteIntrinsics(const capture::Site& site) {
  formats::IntrinsicsDir intrinsics;
  for (const capture::SiteCamera& camera : site.cameras) {
    try {
      intrinsics.cameras[camera.name] = formats::ReadIntrinsics(camera.intrinsics, camera.name);
    } catch (const std::exception& error) {
      intrinsics.unusable[camera.name] = error.what();
    }
  }
  return intrinsics;
}

// Records into `recordings` (created here) and writes its capture.json there.
capture::CaptureRun Recorded(const capture::Site& site, const Projection& projection, const fs::path& intrinsics,
                             const fs::path& recordings, const CaptureArguments& arguments,
                             Interrupts& interrupts) {
  std::error_code error;
  if (!fs::create_directories(recordings, error)) {
    throw InputError(recordings.string() + ": cannot create the recordings folder (" +
                     (error ? error.message() : "it exists") + ")");
  }
  capture::CapturePlan plan{site, projection.sequence_file, projection.sequence, projection.video, intrinsics,
                            ingest::IngestOptions{}, recordings};
  CaptureRunner runner(interrupts, recordings);
  const capture::CaptureRun run = runner.Record(plan, !arguments.no_progress);
  capture::WriteCaptureLog(recordings / "capture.json", plan, run);
  return run;
}

// What provenance.json records of a capture: the site file, the projection's sequence,
// each camera's recording and the markers.
formats::ProvenanceRecord CaptureProvenance(const Projection& projection, const capture::CaptureRun& run,
                                            const CaptureArguments& arguments) {
  formats::ProvenanceRecord record;
  record.command = arguments.command_line;
  record.source = formats::ProvenanceInput{arguments.site, ""};
  record.sequence = formats::ProvenanceInput{projection.sequence_file.string(), ""};
  for (const formats::CameraOutcome& camera : run.cameras) record.videos.emplace_back(camera.name, camera.video);
  record.markers = projection.sequence.markers.spec;
  return record;
}

int Calibrated(const capture::Site& site, const Projection& projection, const capture::CaptureRun& run,
               OutputFolder& out, const CaptureArguments& arguments, const fs::path& recordings) {
  CalibrationInputs inputs;
  inputs.given = formats::TracksOf(run.cameras, projection.sequence.markers_per_array);
  inputs.intrinsics = SiteIntrinsics(site);
  for (const formats::CameraOutcome& camera : run.cameras) {
    if (!camera.ok()) inputs.left_out.emplace_back(camera.name, camera.error);
  }
  inputs.markers = formats::ProjectedMarkers::FromSequence(projection.sequence);
  inputs.missing_reason = [](const std::string& camera) { return "no intrinsics for camera " + camera; };
  inputs.provenance = CaptureProvenance(projection, run, arguments);
  inputs.provenance.intrinsics = capture::SiteIntrinsicsProvenance();
  const auto measurement = ScaleOption(arguments.scale, true);
  CheckScale(measurement, inputs.given, inputs.markers);
  const std::vector<std::string> exports =
      arguments.exports.empty() ? std::vector<std::string>{} : formats::ParseExportFormats(arguments.exports);
  const auto refinement = RefinementOption(arguments.refine_intrinsics, arguments.self_calibration);
  CheckRefinement(refinement, inputs.given.cameras);
  const auto report = formats::DetectReport(run.cameras, projection.sequence_file.string(), projection.sequence);
  const auto write_report = [&](const fs::path& staging) {
    formats::AtomicWrite(staging / "detect_report.json", formats::DumpSchemaJson("detect_report", 1, report));
  };
  const int status =
      CalibrateInto(out, inputs, arguments.options, exports, measurement, write_report, refinement, arguments.json);
  // After the commit: an interruption before it leaves the recordings where they were.
  fs::rename(recordings, out.path() / "recordings");
  return status;
}

int Checked(const Projection& projection, const capture::CaptureRun& run, std::optional<OutputFolder>& out,
            const CaptureArguments& arguments, const StoredResults& stored, const fs::path& recordings) {
  CheckArguments check;
  check.results = arguments.check;
  check.out = arguments.out;
  check.exports = arguments.exports;
  check.command_line = arguments.command_line;
  check.json = arguments.json;
  const formats::Tracks tracks = formats::TracksOf(run.cameras, projection.sequence.markers_per_array);
  formats::ProvenanceRecord provenance = CaptureProvenance(projection, run, arguments);
  bool repaired = false;
  const int status =
      CheckAgainst(stored, tracks, projection.sequence_file.string(), check, out, provenance, &repaired);
  if (repaired) fs::rename(recordings, out->path() / "recordings");  // after the commit, as Calibrated
  return status;
}

// Adds where the recordings are kept to a failure's one line.
std::string WithRecordings(const std::string& message, const fs::path& recordings) {
  return message + "; the recordings are kept in " + recordings.string();
}

}  // namespace

int RunCapture(const CaptureArguments& arguments, Interrupts& interrupts) {
  const bool checking = !arguments.check.empty();
  if (!checking && arguments.out.empty()) throw InputError("--out DIR is needed (the results folder) unless --check");
  if (!arguments.projection.empty() && arguments.sequence.empty()) {
    throw InputError("--projection goes with --sequence (the site file names its own projection)");
  }
  if (checking && arguments.sequence.empty()) {
    throw InputError("--check needs --sequence (the check projection's sequence.json)");
  }
  if (checking && (!arguments.scale.empty() || !arguments.refine_intrinsics.empty())) {
    throw InputError("--scale and --refine-intrinsics are for calibrating, not with --check");
  }
  RefinementOption(arguments.refine_intrinsics, arguments.self_calibration);  // checked before recording
  if (!arguments.exports.empty()) formats::ParseExportFormats(arguments.exports);
  ScaleOption(arguments.scale, true);
  RequireValidOptions(arguments.options);
  const capture::Site site = capture::ReadSite(arguments.site);
  const Projection projection = Projected(site, arguments);
  // The output checked and locked before anything is recorded.
  std::optional<OutputFolder> out;
  if (!arguments.out.empty()) {
    out.emplace(arguments.out, arguments.force, formats::kCalibrationFiles, &interrupts);
    out->Open();
  }
  std::optional<StoredResults> stored;
  if (checking) stored = ReadStored(arguments.check);
  const fs::path beside = !arguments.out.empty() ? PathlibPath(arguments.out)
                                                 : PathlibPath(arguments.check).concat("-check");
  const fs::path recordings = RecordingsFolder(arguments.recordings, beside);
  const fs::path intrinsics = checking ? PathlibPath(arguments.check) / "intrinsics" : fs::path();
  try {
    const capture::CaptureRun run = Recorded(site, projection, intrinsics, recordings, arguments, interrupts);
    if (checking) return Checked(projection, run, out, arguments, *stored, recordings);
    return Calibrated(site, projection, run, *out, arguments, recordings);
  } catch (const OutputBusyError&) {
    throw;
  } catch (const InputError& error) {
    if (!fs::exists(recordings)) throw;
    throw InputError(WithRecordings(error.what(), recordings));
  } catch (const std::exception& error) {
    if (!fs::exists(recordings)) throw;
    // The projector could not play, no camera delivered: exit status 1, as calibproj's.
    std::cerr << "calibproj-native capture: error: " << WithRecordings(error.what(), recordings) << "\n";
    return 1;
  }
}

}  // namespace calibproj::app
