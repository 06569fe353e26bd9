#pragma once
// The projector: the projection video played full screen on the display output that
// drives it, decoded and presented by libmpv, with a log of when each frame was shown.

#include <atomic>
#include <memory>
#include <string>
#include <vector>

namespace calibproj::capture {

struct ProjectorOptions {
  // X display of the projector's output (":0", or a virtual one such as ":99"); empty:
  // the process's DISPLAY. X11 takes it from the process environment, so a display
  // given here becomes the process's DISPLAY.
  std::string display;
  // The screen (monitor) to fill, counted from 0 as the window system lists them; -1:
  // the player's default (the primary).
  int screen = -1;
  // mpv's video outputs, tried in turn: "gpu" where there is a GPU, "x11" (software)
  // where there is none. Never mpv's own default list, which ends with outputs that
  // draw on the terminal and would "play" a projection nobody sees.
  std::string video_output = "gpu,x11";
  // The projection must be playing within this and over within its duration plus this.
  double timeout_s = 20.0;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

// When each frame of the projection was shown.
struct PresentationLog {
  std::vector<double> video_time_s;  // the frame's time in the video
  std::vector<double> shown_s;       // seconds since the playback started (steady clock)
  long long dropped_frames = 0;      // frames the player dropped or showed late
  double duration_s = 0.0;           // from the first frame shown to the end
};

class Projector {
 public:
  explicit Projector(const ProjectorOptions& options);
  ~Projector();
  Projector(const Projector&) = delete;
  Projector& operator=(const Projector&) = delete;

  // Plays `video` to its end, full screen; blocks. Throws std::runtime_error naming the
  // display and the problem when the video cannot be played there (no such display,
  // no such screen, an unreadable file) or the timeout passes; `stop` set from another
  // thread ends the playback at once (the log says how far it got).
  PresentationLog Play(const std::string& video, const std::shared_ptr<std::atomic<bool>>& stop = nullptr);

 private:
  ProjectorOptions options_;
};

}  // namespace calibproj::capture
