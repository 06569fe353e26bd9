#pragma once
// Decoded frames placed on the camera's frame grid by their container timestamps.
//
// A frame's slot is its position on a grid of one frame period (slot 0 = the first
// decoded frame): slots, not decoding indices, are the "camera frames" of the frame
// map, so a camera that dropped frames (phones, IP cameras) keeps its timing. Each
// frame is placed relative to the previous one (a gap of k periods = k - 1 dropped
// frames), so a small error of the period never accumulates into a wrong slot.

#include <stdexcept>
#include <string>

namespace calibproj::video {

struct FrameClockStats {
  int frames = 0;      // frames placed
  int dropped = 0;     // empty slots between placed frames
  int duplicated = 0;  // frames in a slot already taken (or going back in time): skipped
  int untimed = 0;     // frames without a timestamp, placed in the next slot
  int largest_gap = 0; // most slots between two consecutive frames
  // RMS distance (seconds) of the timestamps from the best straight line through
  // them against their slots: the timing jitter.
  double jitter_rms_s = 0.0;
};

class FrameClock {
 public:
  // `period_s` > 0 is the grid period; a gap of more than `max_gap_s` seconds between
  // consecutive frames is an error (a paused recording or a corrupt timestamp would
  // otherwise make a signal of unbounded length). `use_timestamps` false places frames
  // in consecutive slots (for containers whose timestamps are wrong).
  FrameClock(double period_s, double max_gap_s, bool use_timestamps, std::string source);

  // Slot of the next decoded frame with timestamp `seconds` (NaN: none), or -1 when the
  // frame falls into a slot already taken. Throws std::runtime_error naming the
  // source on a gap longer than max_gap_s.
  int Place(double seconds);

  int last_slot() const { return last_slot_; }
  double period_s() const { return period_; }
  FrameClockStats Stats() const;

 private:
  double period_;
  double max_gap_;
  bool use_timestamps_;
  std::string source_;
  int last_slot_ = -1;
  double last_time_ = 0.0;
  FrameClockStats stats_;
  // Sums of the line fit of time against slot (times relative to the first frame).
  double first_time_ = 0.0;
  double sum_s_ = 0, sum_t_ = 0, sum_ss_ = 0, sum_st_ = 0, sum_tt_ = 0;
  int timed_ = 0;
};

}  // namespace calibproj::video
