#include "calibproj/capture/projector.h"

#include "calibproj/video/ffmpeg_log.h"

#include <mpv/client.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <stdexcept>

namespace calibproj::capture {

namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

// One player instance, destroyed (its window closed) on every way out; FFmpeg's log,
// which libmpv takes over, is calibproj's again afterwards.
struct Player {
  mpv_handle* handle = mpv_create();
  ~Player() {
    if (handle != nullptr) mpv_terminate_destroy(handle);
    video::ReclaimFfmpegLog();
  }
};

void SetOption(mpv_handle* mpv, const char* name, const std::string& value) {
  const int code = mpv_set_option_string(mpv, name, value.c_str());
  if (code < 0) {
    throw std::invalid_argument(std::string("projector: the player refuses ") + name + "=" + value + " (" +
                                mpv_error_string(code) + ")");
  }
}

}  // namespace

void ProjectorOptions::Check() const {
  if (screen < -1 || screen > 32) throw std::invalid_argument("projector: screen must be -1 (default) or in [0, 32]");
  if (!(timeout_s > 0.0 && timeout_s <= 3600.0)) throw std::invalid_argument("projector: timeout_s must be in (0, 3600]");
  if (display.find('\0') != std::string::npos || video_output.find('\0') != std::string::npos) {
    throw std::invalid_argument("projector: display and video_output must be text");
  }
  if (video_output.empty()) throw std::invalid_argument("projector: video_output must name mpv outputs (e.g. gpu,x11)");
}

Projector::Projector(const ProjectorOptions& options) : options_(options) { options_.Check(); }

Projector::~Projector() = default;

PresentationLog Projector::Play(const std::string& video, const std::shared_ptr<std::atomic<bool>>& stop) {
  // X11 clients open the display the environment names (see ProjectorOptions::display).
  if (!options_.display.empty()) setenv("DISPLAY", options_.display.c_str(), 1);
  const std::string where =
      "projector (display " + std::string(std::getenv("DISPLAY") != nullptr ? std::getenv("DISPLAY") : "none") +
      (options_.screen >= 0 ? ", screen " + std::to_string(options_.screen) : "") + ")";
  Player player;
  mpv_handle* mpv = player.handle;
  if (mpv == nullptr) throw std::runtime_error(where + ": cannot start the player (libmpv)");
  SetOption(mpv, "config", "no");
  SetOption(mpv, "terminal", "no");
  SetOption(mpv, "idle", "yes");  // the end of the file is an event, not the player's exit
  SetOption(mpv, "fullscreen", "yes");
  SetOption(mpv, "border", "no");
  SetOption(mpv, "ontop", "yes");
  SetOption(mpv, "audio", "no");
  SetOption(mpv, "osc", "no");
  SetOption(mpv, "osd-level", "0");
  SetOption(mpv, "input-default-bindings", "no");
  SetOption(mpv, "input-vo-keyboard", "no");
  SetOption(mpv, "cursor-autohide", "always");
  SetOption(mpv, "hwdec", "no");
  SetOption(mpv, "keep-open", "no");
  if (options_.screen >= 0) {
    SetOption(mpv, "screen", std::to_string(options_.screen));
    SetOption(mpv, "fs-screen", std::to_string(options_.screen));
  }
  SetOption(mpv, "vo", options_.video_output);
  SetOption(mpv, "gpu-context", "x11egl");  // the display's, not a Wayland or DRM one
  mpv_request_log_messages(mpv, "error");
  if (mpv_initialize(mpv) < 0) throw std::runtime_error(where + ": cannot start the player (libmpv)");
  mpv_observe_property(mpv, 1, "time-pos", MPV_FORMAT_DOUBLE);
  mpv_observe_property(mpv, 2, "frame-drop-count", MPV_FORMAT_INT64);
  mpv_observe_property(mpv, 3, "vo-delayed-frame-count", MPV_FORMAT_INT64);
  const char* load[] = {"loadfile", video.c_str(), nullptr};
  if (mpv_command(mpv, load) < 0) throw std::runtime_error(where + ": cannot load " + video);

  PresentationLog log;
  long long dropped = 0, delayed = 0;
  std::string said;  // the player's first error message
  const Clock::time_point asked = Clock::now();
  Clock::time_point first_shown;
  double duration = 0.0;
  while (true) {
    if (stop && stop->load()) break;
    const double waited = SecondsSince(asked);
    if (log.shown_s.empty() && waited > options_.timeout_s) {
      throw std::runtime_error(where + ": nothing shown within " + std::to_string(static_cast<int>(options_.timeout_s)) +
                               " s" + (said.empty() ? "" : " (" + said + ")"));
    }
    if (!log.shown_s.empty() && SecondsSince(first_shown) > duration + options_.timeout_s) {
      throw std::runtime_error(where + ": the projection did not end in time (stalled at " +
                               std::to_string(log.video_time_s.back()) + " s)");
    }
    const mpv_event* event = mpv_wait_event(mpv, 0.05);
    if (event->event_id == MPV_EVENT_NONE) continue;
    if (event->event_id == MPV_EVENT_LOG_MESSAGE) {
      // The first error is the cause (a display that does not open); later ones follow from it.
      const auto* message = static_cast<const mpv_event_log_message*>(event->data);
      if (said.empty()) said = message->text;
      while (!said.empty() && (said.back() == '\n' || said.back() == ' ')) said.pop_back();
    } else if (event->event_id == MPV_EVENT_PROPERTY_CHANGE) {
      const auto* property = static_cast<const mpv_event_property*>(event->data);
      if (property->format == MPV_FORMAT_NONE) continue;
      if (event->reply_userdata == 1) {
        const double time = *static_cast<const double*>(property->data);
        if (log.shown_s.empty()) {
          first_shown = Clock::now();
          double length = 0.0;
          if (mpv_get_property(mpv, "duration", MPV_FORMAT_DOUBLE, &length) >= 0 && std::isfinite(length)) {
            duration = length;
          }
        }
        log.video_time_s.push_back(time);
        log.shown_s.push_back(SecondsSince(first_shown));
      } else if (event->reply_userdata == 2) {
        dropped = *static_cast<const int64_t*>(property->data);
      } else if (event->reply_userdata == 3) {
        delayed = *static_cast<const int64_t*>(property->data);
      }
    } else if (event->event_id == MPV_EVENT_END_FILE) {
      const auto* end = static_cast<const mpv_event_end_file*>(event->data);
      if (end->reason == MPV_END_FILE_REASON_ERROR) {
        throw std::runtime_error(where + ": cannot play " + video + " (" + mpv_error_string(end->error) +
                                 (said.empty() ? "" : "; " + said) + ")");
      }
      break;
    } else if (event->event_id == MPV_EVENT_SHUTDOWN) {
      break;
    }
  }
  if (log.shown_s.empty() && !(stop && stop->load())) {
    throw std::runtime_error(where + ": the player showed nothing of " + video + (said.empty() ? "" : " (" + said + ")"));
  }
  log.dropped_frames = dropped + delayed;
  log.duration_s = log.shown_s.empty() ? 0.0 : SecondsSince(first_shown);
  return log;
}

}  // namespace calibproj::capture
