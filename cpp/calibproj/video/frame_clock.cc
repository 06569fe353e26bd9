#include "calibproj/video/frame_clock.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <utility>

#include "calibproj/common/limits.h"

namespace calibproj::video {

namespace {

// Frames a timestamp may lie behind the previous one and still count as a duplicate.
constexpr double kMaxBackwardFrames = 2.0;

}  // namespace

FrameClock::FrameClock(double period_s, double max_gap_s, bool use_timestamps, std::string source)
    : period_(period_s), max_gap_(max_gap_s), use_timestamps_(use_timestamps), source_(std::move(source)) {
  if (!(period_ > 0.0) || !std::isfinite(period_)) throw std::invalid_argument(source_ + ": no frame period");
  if (!(max_gap_ > 0.0) || !std::isfinite(max_gap_)) throw std::invalid_argument("max_frame_gap_s must be positive");
}

int FrameClock::Place(double seconds) {
  if (!use_timestamps_ || !std::isfinite(seconds)) {
    if (use_timestamps_) ++stats_.untimed;
    ++stats_.frames;
    if (last_slot_ >= 0) last_time_ += period_;
    return ++last_slot_;
  }
  int slot = 0;
  if (last_slot_ < 0) {
    first_time_ = seconds;
  } else {
    const double steps = std::round((seconds - last_time_) / period_);
    if (steps < 1.0) {
      // A timestamp a frame or two early is a duplicate; one far back is a reset
      // (concatenated recordings), which would silently drop everything after it.
      if (last_time_ - seconds > kMaxBackwardFrames * period_) {
        std::ostringstream message;
        message << source_ << ": the timestamps go back by " << last_time_ - seconds << " s after frame "
                << stats_.frames - 1 << " (joined recordings?); set use_timestamps to false to use the decoding order";
        throw std::runtime_error(message.str());
      }
      ++stats_.duplicated;
      return -1;
    }
    if ((steps - 1.0) * period_ > max_gap_) {
      std::ostringstream message;
      message << source_ << ": the timestamps jump by " << seconds - last_time_ << " s after frame "
              << stats_.frames - 1 << " (more than max_frame_gap_s = " << max_gap_ << " s)";
      throw std::runtime_error(message.str());
    }
    // Slots index the signal, which would grow to the slot.
    if (last_slot_ + steps > limits::kMaxFrames) {
      std::ostringstream message;
      message << source_ << ": the timestamps reach past frame " << limits::kMaxFrames << " after frame "
              << stats_.frames - 1;
      throw std::runtime_error(message.str());
    }
    const int gap = static_cast<int>(steps);
    slot = last_slot_ + gap;
    stats_.dropped += gap - 1;
    stats_.largest_gap = std::max(stats_.largest_gap, gap);
  }
  last_slot_ = slot;
  last_time_ = seconds;
  ++stats_.frames;
  const double s = slot, t = seconds - first_time_;
  sum_s_ += s;
  sum_t_ += t;
  sum_ss_ += s * s;
  sum_st_ += s * t;
  sum_tt_ += t * t;
  ++timed_;
  return slot;
}

FrameClockStats FrameClock::Stats() const {
  FrameClockStats stats = stats_;
  const double n = timed_;
  const double denominator = n * sum_ss_ - sum_s_ * sum_s_;
  if (timed_ >= 3 && denominator > 0.0) {
    // Residual sum of squares of the line fit, from the sums.
    const double slope = (n * sum_st_ - sum_s_ * sum_t_) / denominator;
    const double intercept = (sum_t_ - slope * sum_s_) / n;
    const double residual = sum_tt_ - intercept * sum_t_ - slope * sum_st_;
    stats.jitter_rms_s = std::sqrt(std::max(0.0, residual) / n);
  }
  return stats;
}

}  // namespace calibproj::video
