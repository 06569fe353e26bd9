#pragma once
// The projector's brightness over time, as far as the sequence says it (light codes,
// white and black reference frames), and what a camera exposing over a window sees.
//
// Time is in projector frames: frame k is shown during [k, k + 1). Frames whose
// brightness the sequence does not fix (MSM patterns, anything outside the sequence)
// are unknown and never enter a model of the camera signal.

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

namespace calibproj::sync {

// A binary light code: bit i is shown on projector frames
// [first_frame + i * frames_per_bit, first_frame + (i + 1) * frames_per_bit).
struct LightCode {
  std::vector<int> bits;
  int frames_per_bit = 1;
  int first_frame = 0;

  int FrameCount() const { return static_cast<int>(bits.size()) * frames_per_bit; }
  int EndFrame() const { return first_frame + FrameCount(); }  // one past the last frame

  // Throws std::invalid_argument naming `what` for an empty code, bits other than 0/1,
  // a constant code or a non-positive frames_per_bit.
  void Check(const char* what) const;
};

inline bool operator==(const LightCode& a, const LightCode& b) {
  return a.bits == b.bits && a.frames_per_bit == b.frames_per_bit && a.first_frame == b.first_frame;
}

// Projector frames [begin, end) whose levels a model may use.
struct FrameWindow {
  int begin = 0;
  int end = 0;
  int size() const { return end - begin; }
};

class LightTimeline {
 public:
  // levels[k] in [0, 1] is the share of full white shown on projector frame k; NaN
  // marks a frame whose brightness is unknown.
  explicit LightTimeline(std::vector<double> levels);

  int frame_count() const { return static_cast<int>(levels_.size()); }
  double Level(int frame) const;  // NaN outside the sequence

  // Level shown at time t (right-continuous at frame changes).
  double LevelAt(double t) const { return Level(static_cast<int>(std::floor(t))); }

  // Mean level over [t, t + duration); the level at t when duration is 0. Only valid
  // when every frame it touches is known. Inline: the code fits' grid searches call it
  // millions of times per camera.
  double Average(double t, double duration) const {
    if (!(duration > 1e-9)) return LevelAt(t);
    return (Integral(t + duration) - Integral(t)) / duration;
  }

  // Frames of [code.first_frame - context, code.EndFrame() + context) that form one
  // run of known frames with the code (the window stops at the first unknown frame).
  FrameWindow KnownWindow(const LightCode& code, int context_before, int context_after) const;

 private:
  // Integral of the level from 0 to t (unknown frames as 0).
  double Integral(double t) const {
    const double clamped = std::clamp(t, 0.0, static_cast<double>(frame_count()));
    const int frame = std::min(static_cast<int>(clamped), frame_count() - 1);
    return cumulative_[frame] + (clamped - frame) * known_levels_[frame];
  }

  std::vector<double> levels_;
  std::vector<double> known_levels_;  // levels_ with unknown frames as 0
  std::vector<double> cumulative_;    // cumulative_[k] = sum of known_levels_[0 .. k - 1]
};

}  // namespace calibproj::sync
