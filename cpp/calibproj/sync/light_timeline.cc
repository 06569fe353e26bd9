#include "calibproj/sync/light_timeline.h"

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <string>

#include "calibproj/common/limits.h"

namespace calibproj::sync {

void LightCode::Check(const char* what) const {
  const std::string name(what);
  if (bits.empty()) throw std::invalid_argument(name + ": the light code has no bits");
  if (frames_per_bit < 1) throw std::invalid_argument(name + ": frames_per_bit must be at least 1");
  // Within the longest sequence, so that EndFrame() cannot overflow.
  const long long end = first_frame + static_cast<long long>(bits.size()) * frames_per_bit;
  if (first_frame < 0 || end > limits::kMaxFrames) {
    throw std::invalid_argument(name + ": the light code must lie within frames 0.." +
                                std::to_string(limits::kMaxFrames) + ", got first_frame " +
                                std::to_string(first_frame) + " and " + std::to_string(bits.size()) + " bits of " +
                                std::to_string(frames_per_bit) + " frames");
  }
  int ones = 0;
  for (int bit : bits) {
    if (bit != 0 && bit != 1) throw std::invalid_argument(name + ": light code bits must be 0 or 1");
    ones += bit;
  }
  if (ones == 0 || ones == static_cast<int>(bits.size())) {
    throw std::invalid_argument(name + ": a constant light code cannot be located in time");
  }
}

LightTimeline::LightTimeline(std::vector<double> levels) : levels_(std::move(levels)) {
  if (levels_.size() > static_cast<std::size_t>(limits::kMaxFrames)) {
    throw std::invalid_argument("light timeline: more than " + std::to_string(limits::kMaxFrames) + " frames");
  }
  cumulative_.assign(levels_.size() + 1, 0.0);
  known_levels_.assign(levels_.size(), 0.0);
  for (std::size_t k = 0; k < levels_.size(); ++k) {
    const double level = levels_[k];
    if (!std::isnan(level) && (level < 0.0 || level > 1.0)) {
      throw std::invalid_argument("light timeline: level " + std::to_string(level) + " of frame " +
                                  std::to_string(k) + " is outside [0, 1]");
    }
    known_levels_[k] = std::isnan(level) ? 0.0 : level;
    cumulative_[k + 1] = cumulative_[k] + known_levels_[k];
  }
}

double LightTimeline::Level(int frame) const {
  if (frame < 0 || frame >= frame_count()) return std::numeric_limits<double>::quiet_NaN();
  return levels_[frame];
}

FrameWindow LightTimeline::KnownWindow(const LightCode& code, int context_before, int context_after) const {
  FrameWindow window{code.first_frame, code.EndFrame()};
  const auto known = [&](int frame) { return !std::isnan(Level(frame)); };
  while (window.begin > code.first_frame - context_before && known(window.begin - 1)) --window.begin;
  while (window.end < code.EndFrame() + context_after && known(window.end)) ++window.end;
  return window;
}

}  // namespace calibproj::sync
