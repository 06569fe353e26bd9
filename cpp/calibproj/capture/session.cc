#include "calibproj/capture/session.h"

#include <nlohmann/json.hpp>

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <exception>
#include <mutex>
#include <thread>

#include "calibproj/formats/files.h"
#include "calibproj/formats/intrinsics_file.h"

namespace calibproj::capture {

namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;
constexpr auto kWaitSlice = std::chrono::milliseconds(100);  // how soon `abort` is seen

struct CameraState {
  int frames = 0;
  std::optional<double> first_s;
  std::optional<double> last_s;
  std::optional<std::pair<int, double>> shown;  // frames and time at the last status line
  bool done = false;
};

std::string Joined(const std::vector<std::string>& items, const std::string& separator) {
  std::string out;
  for (const auto& item : items) out += (out.empty() ? "" : separator) + item;
  return out;
}

std::string Fixed(double value, int decimals) {
  char text[64];
  std::snprintf(text, sizeof text, "%.*f", decimals, value);
  return text;
}

class Session {
 public:
  Session(const CapturePlan& plan, std::shared_ptr<std::atomic<bool>> abort, const CaptureLogger& log)
      : plan_(plan), abort_(std::move(abort)), log_(log), started_(Clock::now()), states_(plan.site.cameras.size()) {
    if (!abort_) abort_ = std::make_shared<std::atomic<bool>>(false);
    run_.cameras.resize(plan.site.cameras.size());
    run_.delivered.resize(plan.site.cameras.size());
    for (const SiteCamera& camera : plan.site.cameras) {
      video::SourceOptions source = camera.options;
      source.live = true;
      source.stop = std::make_shared<std::atomic<bool>>(false);  // this capture's own
      source.record_path = (plan.recordings / (camera.name + ".mkv")).string();
      sources_.push_back(std::move(source));
    }
  }

  ~Session() {
    player_stop_->store(true);
    for (auto& source : sources_) source.stop->store(true);
    if (player_.joinable()) player_.join();
    for (auto& thread : threads_) {
      if (thread.joinable()) thread.join();
    }
  }

  CaptureRun Run() {
    for (std::size_t k = 0; k < sources_.size(); ++k) threads_.emplace_back([this, k] { Ingest(k); });
    Say(false, "capture: opening " + std::to_string(sources_.size()) + " camera(s)");
    WaitForReady();
    Play();
    WaitForEnd();
    for (auto& thread : threads_) thread.join();
    if (abort_->load()) throw CaptureInterrupted("capture interrupted");
    for (std::size_t k = 0; k < states_.size(); ++k) {
      run_.delivered[k].frames = states_[k].frames;
      run_.delivered[k].first_frame_s = states_[k].first_s;
      run_.delivered[k].recording = plan_.site.cameras[k].name + ".mkv";
    }
    return std::move(run_);
  }

 private:
  double Now() const { return std::chrono::duration<double>(Clock::now() - started_).count(); }

  // Never throws: a failing logger must not end a camera's thread.
  void Say(bool error, const std::string& line) const noexcept {
    if (!log_) return;
    try {
      log_(error, line);
    } catch (...) {
    }
  }

  // One camera's thread: its intrinsics read, its source ingested live.
  void Ingest(std::size_t k) {
    const SiteCamera& camera = plan_.site.cameras[k];
    formats::CameraOutcome& outcome = run_.cameras[k];  // this thread's alone until it ends
    outcome.name = camera.name;
    outcome.video = camera.source;
    try {
      formats::CameraIntrinsics intrinsics;
      try {
        const fs::path file = plan_.intrinsics_folder.empty()
                                  ? camera.intrinsics
                                  : formats::IntrinsicsFileOf(plan_.intrinsics_folder, camera.name);
        intrinsics = formats::ReadIntrinsics(file, camera.name);
        outcome.intrinsics = file.string();
      } catch (const std::exception& error) {
        outcome.intrinsics = error.what();  // the message stands where its path would
        throw;
      }
      ingest::IngestOptions options = plan_.options;
      if (camera.exposure_s > 0.0) options.exposure_s = camera.exposure_s;
      options.decode_threads =
          ingest::SharedDecodeThreads(options.decode_threads, static_cast<int>(plan_.site.cameras.size()));
      outcome.result = ingest::IngestCamera(camera.source, plan_.sequence, intrinsics, outcome.intrinsics, options,
                                            [this, k](int decoded, int) { Delivered(k, decoded); }, sources_[k]);
    } catch (const std::exception& error) {
      outcome.error = error.what();
    }
    if (!abort_->load()) {
      if (outcome.ok()) {
        Say(false, "camera " + camera.name + ": " + std::to_string(outcome.result.centres.size()) + " MSMs");
      } else {
        Say(true, "camera " + camera.name + " failed: " + outcome.error);
      }
    }
    std::lock_guard<std::mutex> lock(mutex_);
    states_[k].done = true;
    changed_.notify_all();
  }

  void Delivered(std::size_t k, int decoded) {
    std::lock_guard<std::mutex> lock(mutex_);
    CameraState& state = states_[k];
    if (!state.first_s) state.first_s = Now();
    state.frames = decoded;
    state.last_s = Now();
    changed_.notify_all();
  }

  // Waits until done() (under the lock) or timeout_s; false on the timeout or an abort.
  template <typename Done>
  bool WaitFor(Done done, double timeout_s) {
    const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                             std::chrono::duration<double>(timeout_s));
    std::unique_lock<std::mutex> lock(mutex_);
    while (!done()) {
      if (abort_->load() || Clock::now() >= deadline) return false;
      changed_.wait_until(lock, std::min(deadline, Clock::now() + kWaitSlice));
    }
    return true;
  }

  // The cameras (by index) for which `late` holds, under the lock.
  template <typename Late>
  std::vector<std::size_t> Cameras(Late late) {
    std::lock_guard<std::mutex> lock(mutex_);
    std::vector<std::size_t> found;
    for (std::size_t k = 0; k < states_.size(); ++k) {
      if (late(states_[k])) found.push_back(k);
    }
    return found;
  }

  std::string Names(const std::vector<std::size_t>& cameras) const {
    std::vector<std::string> names;
    for (std::size_t k : cameras) names.push_back(plan_.site.cameras[k].name);
    return Joined(names, ", ");
  }

  void Stop(const std::vector<std::size_t>& cameras) {
    for (std::size_t k : cameras) sources_[k].stop->store(true);
  }

  void ThrowIfAborted() const {
    if (abort_->load()) throw CaptureInterrupted("capture interrupted");
  }

  void WaitForReady() {
    const auto ready = [this] {
      for (const CameraState& state : states_) {
        if (!state.first_s && !state.done) return false;
      }
      return true;
    };
    if (!WaitFor(ready, plan_.site.ready_s)) {
      ThrowIfAborted();
      const auto late = Cameras([](const CameraState& s) { return !s.first_s && !s.done; });
      Say(true, "capture: no frames within " + Fixed(plan_.site.ready_s, 0) + " s from " + Names(late) +
                    ": left out");
      Stop(late);
    }
    const auto delivering = Cameras([](const CameraState& s) { return !s.done; });
    if (!delivering.empty()) return;
    WaitFor([this] { return AllDone(); }, 60.0);  // the stopped ones give their reasons
    std::vector<std::string> reasons;
    for (const auto& outcome : run_.cameras) reasons.push_back(outcome.name + ": " + outcome.error);
    throw std::runtime_error("capture: no camera delivers frames; nothing to calibrate (" + Joined(reasons, "; ") +
                             ")");
  }

  bool AllDone() const {
    for (const CameraState& state : states_) {
      if (!state.done) return false;
    }
    return true;
  }

  // Plays the projection in a thread of its own, with status lines while it plays.
  void Play() {
    Say(false, "capture: projecting " + plan_.video.string());
    run_.projection_started_s = Now();
    player_ = std::thread([this] {
      try {
        run_.projection = Projector(plan_.site.projector).Play(plan_.video.string(), player_stop_);
      } catch (...) {
        play_failure_ = std::current_exception();
      }
      std::lock_guard<std::mutex> lock(mutex_);
      played_ = true;
      changed_.notify_all();
    });
    const double interval = plan_.status_interval_s;
    while (!WaitFor([this] { return played_; }, interval > 0.0 ? interval : 3600.0)) {
      if (abort_->load()) {
        player_stop_->store(true);  // ends the playback at once
        break;
      }
      if (interval > 0.0) StatusLines();
    }
    player_.join();
    ThrowIfAborted();
    if (play_failure_) std::rethrow_exception(play_failure_);
    const PresentationLog& log = run_.projection;
    Say(false, "capture: projection shown in " + Fixed(log.duration_s, 1) + " s (" +
                   std::to_string(log.shown_s.size()) + " frames logged, " + std::to_string(log.dropped_frames) +
                   " dropped or late)");
  }

  void WaitForEnd() {
    const auto ended = Clock::now();
    if (!WaitFor([this] { return AllDone(); }, plan_.site.end_s)) {
      ThrowIfAborted();
      const auto late = Cameras([](const CameraState& s) { return !s.done; });
      Say(true, "capture: " + Names(late) + " still without the end light code " + Fixed(plan_.site.end_s, 0) +
                    " s after the projection: stopped");
      Stop(late);
    }
    WaitFor([this] { return AllDone(); }, 3600.0);  // a stopped source ends at once
    ThrowIfAborted();
    run_.cameras_done_after_end_s = std::chrono::duration<double>(Clock::now() - ended).count();
    Say(false, "capture: every camera ingested " + Fixed(run_.cameras_done_after_end_s, 1) +
                   " s after the projection ended");
  }

  // A line per camera: frames, and the rate since the last line (the first frames
  // arrive in a burst, those read ahead at opening).
  void StatusLines() {
    std::vector<std::string> lines;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      for (std::size_t k = 0; k < states_.size(); ++k) {
        CameraState& state = states_[k];
        const std::string name = "camera " + plan_.site.cameras[k].name;
        if (state.done) {
          lines.push_back(name + (run_.cameras[k].ok() ? ": done" : ": failed"));
        } else if (!state.first_s) {
          lines.push_back(name + ": waiting for frames");
        } else {
          const auto [frames, since] = state.shown.value_or(std::make_pair(state.frames, *state.last_s));
          const double span = *state.last_s - since;
          const std::string rate = span > 0.5 ? ", " + Fixed((state.frames - frames) / span, 1) + " fps" : "";
          state.shown = std::make_pair(state.frames, *state.last_s);
          lines.push_back(name + ": " + std::to_string(state.frames) + " frames" + rate);
        }
      }
    }
    for (const auto& line : lines) Say(false, line);
  }

  const CapturePlan& plan_;
  std::shared_ptr<std::atomic<bool>> abort_;
  std::shared_ptr<std::atomic<bool>> player_stop_ = std::make_shared<std::atomic<bool>>(false);
  const CaptureLogger& log_;
  const Clock::time_point started_;
  std::vector<video::SourceOptions> sources_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<CameraState> states_;  // under mutex_
  CaptureRun run_;
  std::vector<std::thread> threads_;
  std::thread player_;  // members, not locals: the destructor may be the one joining it
  bool played_ = false;  // under mutex_
  std::exception_ptr play_failure_;
};

nlohmann::ordered_json OrNull(const std::optional<double>& value) {
  return value ? nlohmann::ordered_json(*value) : nlohmann::ordered_json(nullptr);
}

}  // namespace

CaptureRun Record(const CapturePlan& plan, const std::shared_ptr<std::atomic<bool>>& abort,
                  const CaptureLogger& log) {
  if (plan.site.cameras.empty()) throw std::invalid_argument("capture: the site has no cameras");
  return Session(plan, abort, log).Run();
}

void WriteCaptureLog(const fs::path& path, const CapturePlan& plan, const CaptureRun& run) {
  nlohmann::ordered_json cameras = nlohmann::ordered_json::object();
  for (std::size_t k = 0; k < run.cameras.size(); ++k) {
    const formats::CameraOutcome& outcome = run.cameras[k];
    cameras[outcome.name] = {{"source", outcome.video},
                             {"recording", run.delivered[k].recording},
                             {"frames", run.delivered[k].frames},
                             {"first_frame_s", OrNull(run.delivered[k].first_frame_s)},
                             {"error", outcome.ok() ? nlohmann::ordered_json(nullptr)
                                                    : nlohmann::ordered_json(outcome.error)}};
  }
  const PresentationLog& shown = run.projection;
  const nlohmann::ordered_json projection = {{"video", plan.video.string()},
                                             {"sequence", plan.sequence_file.string()},
                                             {"started_s", run.projection_started_s},
                                             {"duration_s", shown.duration_s},
                                             {"frames_logged", shown.shown_s.size()},
                                             {"dropped_frames", shown.dropped_frames},
                                             {"cameras_done_after_end_s", run.cameras_done_after_end_s},
                                             {"video_time_s", shown.video_time_s},
                                             {"shown_s", shown.shown_s}};
  const nlohmann::ordered_json body = {{"site", plan.site.path.string()},
                                       {"recordings", plan.recordings.string()},
                                       {"cameras", cameras},
                                       {"projection", projection}};
  formats::AtomicWrite(path, formats::DumpSchemaJson("capture", 1, body));
}

}  // namespace calibproj::capture
