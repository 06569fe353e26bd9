#include "video_ingest.h"

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <thread>
#include <type_traits>
#include <vector>

#include "calibproj/detect/option_table.h"
#include "calibproj/formats/files.h"
#include "calibproj/formats/intrinsics_file.h"
#include "calibproj/ingest/option_table.h"
#include "table_flags.h"

namespace calibproj::app {

using formats::CameraIntrinsics;
using formats::CameraOutcome;
using formats::InputError;
using formats::ReadIntrinsics;

namespace fs = std::filesystem;

namespace {

const std::vector<std::string> kVideoSuffixes = {".mp4", ".mov", ".mkv", ".avi", ".m4v", ".mts", ".webm"};

std::string Trim(const std::string& text) {
  const auto first = text.find_first_not_of(" \t");
  if (first == std::string::npos) return "";
  return text.substr(first, text.find_last_not_of(" \t") - first + 1);
}

std::string Quoted(const std::string& text) { return "'" + text + "'"; }

std::string Joined(const std::vector<std::string>& items) {
  std::string out;
  for (const auto& item : items) out += (out.empty() ? "" : ", ") + item;
  return out;
}

// NAME=VALUE split at the first '='; false when there is no '=' or no name.
bool SplitAssignment(const std::string& item, std::string* name, std::string* value) {
  const auto equals = item.find('=');
  if (equals == std::string::npos) return false;
  *name = Trim(item.substr(0, equals));
  *value = Trim(item.substr(equals + 1));
  return !name->empty();
}

// A detector option's value in the field's type, as Python's literal syntax writes it.
template <typename Field>
void ParseOptionValue(const std::string& name, const std::string& text, Field* field) {
  const auto bad = [&](const char* type) {
    return InputError("detector option " + name + ": " + Quoted(text) + " is not " + type);
  };
  if constexpr (std::is_same_v<Field, bool>) {
    if (text == "True" || text == "true" || text == "1") {
      *field = true;
    } else if (text == "False" || text == "false" || text == "0") {
      *field = false;
    } else {
      throw bad("True or False");
    }
  } else {
    size_t used = 0;
    try {
      if constexpr (std::is_integral_v<Field>) {
        *field = static_cast<Field>(std::stoi(text, &used));
      } else {
        *field = static_cast<Field>(std::stod(text, &used));
      }
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != text.size()) throw bad(std::is_integral_v<Field> ? "an integer" : "a number");
  }
}

// Applies --detector-option NAME=VALUE items to the options of the sequence's marker
// system, with calibproj.detect_markers' names and messages.
void ApplyDetectorOptions(const std::vector<std::string>& items, const std::string& system,
                          detect::DetectorOptions* options) {
  std::map<std::string, std::string> values;  // the last value of a name counts
  for (const std::string& item : items) {
    std::string name, value;
    if (!SplitAssignment(item, &name, &value)) {
      throw InputError("--detector-option expects NAME=VALUE, got " + Quoted(item));
    }
    values[name] = value;
  }
  detect::CornerRefinementOptions& refinement =
      system == "aruco" ? options->aruco.refinement : options->apriltag.refinement;
  if (const auto method = values.find("corner_refinement"); method != values.end()) {
    const std::map<std::string, detect::CornerRefinement> methods = {
        {"none", detect::CornerRefinement::kNone},
        {"subpix", detect::CornerRefinement::kSubpix},
        {"edges", detect::CornerRefinement::kEdges}};
    if (!methods.count(method->second)) {
      throw InputError("corner_refinement: unknown method " + Quoted(method->second) +
                       " (choose from none, subpix, edges)");
    }
    refinement.method = methods.at(method->second);
    values.erase(method);
  }
  std::vector<std::string> known = {"corner_refinement"};
  const auto set = [&](const std::string& name, auto& field) {
    known.push_back(name);
    if (const auto value = values.find(name); value != values.end()) {
      ParseOptionValue(name, value->second, &field);
      values.erase(value);
    }
  };
  if (system == "aruco") {
    detect::VisitArucoOptions(options->aruco, set);
  } else {
    detect::VisitAprilTagOptions(options->apriltag, set);
  }
  if (!values.empty()) {
    std::vector<std::string> unknown;
    for (const auto& entry : values) unknown.push_back(entry.first);
    std::sort(known.begin(), known.end());
    throw InputError("unknown " + system + " detection option(s) " + Joined(unknown) + " (choose from " +
                     Joined(known) + ")");
  }
  try {
    if (system == "aruco") {
      options->aruco.Check();
    } else {
      options->apriltag.Check();
    }
  } catch (const std::invalid_argument& error) {
    throw InputError(error.what());
  }
}

// --exposure CAMERA=SECONDS items, for cameras that have a video.
std::map<std::string, double> ParseExposures(const std::vector<std::string>& items,
                                             const std::map<std::string, fs::path>& videos) {
  std::map<std::string, double> exposures;
  for (const std::string& item : items) {
    std::string name, text;
    double seconds = -1.0;
    if (SplitAssignment(item, &name, &text)) {
      try {
        size_t used = 0;
        seconds = std::stod(text, &used);
        if (used != text.size()) seconds = -1.0;
      } catch (const std::exception&) {
        seconds = -1.0;
      }
    }
    if (!ingest::ValidKnownExposure(seconds)) {
      throw InputError("--exposure expects CAMERA=SECONDS with 0 < SECONDS <= 1, got " + Quoted(item));
    }
    exposures[name] = seconds;
  }
  std::vector<std::string> unknown;
  for (const auto& entry : exposures) {
    if (!videos.count(entry.first)) unknown.push_back(entry.first);
  }
  if (!unknown.empty()) throw InputError("exposures given for camera(s) without a video: " + Joined(unknown));
  return exposures;
}

std::string Lower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return std::tolower(c); });
  return text;
}

bool HasSuffix(const fs::path& path, const std::vector<std::string>& suffixes) {
  return std::find(suffixes.begin(), suffixes.end(), Lower(path.extension().string())) != suffixes.end();
}


// The camera's intrinsics file, read; InputError with the message the camera reports.
CameraIntrinsics IntrinsicsFor(const fs::path& folder, const std::string& name, std::string* source) {
  const fs::path path = formats::IntrinsicsFileOf(folder, name);
  *source = path.string();
  return ReadIntrinsics(path);
}

// Progress lines on stderr, a few per camera, never interleaved.
class ProgressPrinter {
 public:
  explicit ProgressPrinter(bool enabled) : enabled_(enabled) {}

  ingest::ProgressCallback For(const std::string& name) {
    if (!enabled_) return {};
    return [this, name, next = std::make_shared<int>(0)](int decoded, int total) {
      const int percent = total > 0 ? std::min(100, 100 * decoded / total) : 0;
      if (percent < *next) return;
      *next = percent / 25 * 25 + 25;
      std::lock_guard<std::mutex> lock(mutex_);
      std::cerr << name << ": " << decoded << "/" << total << " frames decoded\n";
    };
  }

  void Say(const std::string& line) {
    std::lock_guard<std::mutex> lock(mutex_);
    std::cerr << line << "\n";
  }

 private:
  bool enabled_;
  std::mutex mutex_;
};

// What every camera's ingest shares: the options, and the known exposures per camera.
struct IngestSetup {
  ingest::IngestOptions options;
  std::map<std::string, double> exposures;

  // Its options for one of `cameras_at_once` cameras ingested together.
  ingest::IngestOptions For(const std::string& camera, int cameras_at_once) const {
    ingest::IngestOptions own = options;
    if (const auto exposure = exposures.find(camera); exposure != exposures.end()) own.exposure_s = exposure->second;
    own.decode_threads = ingest::SharedDecodeThreads(own.decode_threads, cameras_at_once);
    return own;
  }
};

CameraOutcome IngestOne(const std::string& name, const fs::path& video, const IntrinsicsLookup& intrinsics_of,
                        const ingest::IngestOptions& options, const ingest::SequenceDescription& sequence,
                        ProgressPrinter& printer) {
  CameraOutcome outcome{name, video.string(), "", "", {}};
  try {
    const CameraIntrinsics intrinsics = intrinsics_of(name, &outcome.intrinsics);
    outcome.result =
        ingest::IngestCamera(video.string(), sequence, intrinsics, outcome.intrinsics, options, printer.For(name));
  } catch (const std::exception& error) {
    outcome.error = error.what();
    // Without a readable intrinsics file the message stands where its path would.
    if (outcome.intrinsics.empty()) outcome.intrinsics = outcome.error;
    printer.Say("camera " + name + ": " + outcome.error);
    return outcome;
  }
  printer.Say("camera " + name + ": " + std::to_string(outcome.result.centres.size()) + " MSMs");
  return outcome;
}

// Every camera through the ingest, `workers` at a time; results in name order.
std::vector<CameraOutcome> IngestAll(const std::map<std::string, fs::path>& videos, const IntrinsicsLookup& intrinsics_of,
                                     const VideoIngestArguments& arguments, const IngestSetup& setup,
                                     const ingest::SequenceDescription& sequence) {
  const std::vector<std::pair<std::string, fs::path>> jobs(videos.begin(), videos.end());
  std::vector<CameraOutcome> outcomes(jobs.size());
  ProgressPrinter printer(!arguments.no_progress);
  std::atomic<size_t> next{0};
  const size_t threads = std::min(jobs.size(), static_cast<size_t>(std::max(1, arguments.workers)));
  const auto work = [&] {
    for (size_t k = next++; k < jobs.size(); k = next++) {
      const ingest::IngestOptions options = setup.For(jobs[k].first, static_cast<int>(threads));
      outcomes[k] = IngestOne(jobs[k].first, jobs[k].second, intrinsics_of, options, sequence, printer);
    }
  };
  std::vector<std::thread> pool;
  for (size_t t = 0; t < threads; ++t) pool.emplace_back(work);
  for (auto& thread : pool) thread.join();
  return outcomes;
}

}  // namespace

std::map<std::string, fs::path> VideoPaths(const fs::path& folder) {
  if (!fs::is_directory(folder)) throw InputError(folder.string() + ": no such videos folder");
  std::map<std::string, fs::path> paths;
  for (const auto& entry : fs::directory_iterator(folder)) {
    if (!entry.is_regular_file() || !HasSuffix(entry.path(), kVideoSuffixes)) continue;
    const std::string name = entry.path().stem().string();
    if (paths.count(name)) throw InputError(entry.path().string() + ": a second video for camera '" + name + "'");
    paths[name] = entry.path();
  }
  if (paths.empty()) {
    std::string patterns;
    for (const auto& suffix : kVideoSuffixes) patterns += (patterns.empty() ? "*" : ", *") + suffix;
    throw InputError(folder.string() + ": no videos (" + patterns + ")");
  }
  return paths;
}

bool VideoIngestArguments::AnyKnobChanged() const {
  // Both tables walked in the same order: the k-th knob of one is the k-th of the other.
  std::vector<std::string> values, defaults;
  const auto text_into = [](std::vector<std::string>* texts) {
    return [texts](const std::string&, const auto& field, const std::string&) {
      std::ostringstream text;
      text.precision(17);
      if constexpr (std::is_enum_v<std::decay_t<decltype(field)>>) {
        text << static_cast<int>(field);
      } else {
        text << field;
      }
      texts->push_back(text.str());
    };
  };
  ingest::IngestOptions unchanged;
  ingest::VisitIngestOptions(options, text_into(&values));
  ingest::VisitIngestOptions(unchanged, text_into(&defaults));
  return values != defaults;
}

void AddVideoIngestFlags(CLI::App* command, VideoIngestArguments* arguments, const std::vector<std::string>& exclude) {
  command->add_option("--workers", arguments->workers, "cameras processed at once")->capture_default_str();
  SharedFlag(command, "--detector-option", arguments->detector_options)->allow_extra_args(false);
  SharedFlag(command, "--exposure", arguments->exposures)->allow_extra_args(false);
  SharedFlag(command, "--no-progress", arguments->no_progress);
  // One flag per knob of the ingest's table, from which the Python IngestOptions and
  // its flags are made too: both commands take the same command lines.
  const auto flag = TableFlags(command, "ingest options");
  ingest::VisitIngestOptions(arguments->options, [&](const std::string& name, auto& field, const std::string& help) {
    if (std::find(exclude.begin(), exclude.end(), name) == exclude.end()) flag(name, field, help);
  });
}

std::vector<CameraOutcome> IngestVideos(const std::string& videos, const std::string& intrinsics,
                                        const ingest::SequenceDescription& sequence,
                                        const VideoIngestArguments& arguments) {
  return IngestVideos(
      videos, [&](const std::string& name, std::string* source) { return IntrinsicsFor(intrinsics, name, source); },
      sequence, arguments);
}

std::vector<CameraOutcome> IngestVideos(const std::string& videos, const IntrinsicsLookup& intrinsics_of,
                                        const ingest::SequenceDescription& sequence,
                                        const VideoIngestArguments& arguments) {
  const auto paths = VideoPaths(videos);
  RequireValidOptions(arguments.options);
  IngestSetup setup{arguments.options, ParseExposures(arguments.exposures, paths)};
  ApplyDetectorOptions(arguments.detector_options, sequence.markers.system,
                       &setup.options.detector);
  return IngestAll(paths, intrinsics_of, arguments, setup, sequence);
}

}  // namespace calibproj::app
