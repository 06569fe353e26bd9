#pragma once
// The projector's brightness over time, as far as the sequence says it (light codes,
// white and black reference frames), and what a camera exposing over a window sees.
//
// Time is in projector frames: frame k is shown during [k, k + 1). Frames whose
// brightness the sequence does not fix (MSM patterns, anything outside the sequence)
// are unknown and never enter a model of the camera signal.

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
  // when every frame it touches is known.
  double Average(double t, double duration) const;

  // Frames of [code.first_frame - context, code.EndFrame() + context) that form one
  // run of known frames with the code (the window stops at the first unknown frame).
  FrameWindow KnownWindow(const LightCode& code, int context_before, int context_after) const;

 private:
  double Integral(double t) const;  // integral of the level from 0 to t

  std::vector<double> levels_;
  std::vector<double> cumulative_;  // cumulative_[k] = sum of levels_[0 .. k - 1] (unknown as 0)
};

}  // namespace calibproj::sync
