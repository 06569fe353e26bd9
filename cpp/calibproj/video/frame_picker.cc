#include "calibproj/video/frame_picker.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace calibproj::video {

namespace {

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument("frame picking options: " + message);
}

}  // namespace

void PickOptions::Check() const {
  Require(margin >= 0.0, "margin must be non-negative");
  Require(average_frames >= 1 && average_frames <= 8, "average_frames must be in [1, 8]");
  Require(spare_frames >= 0 && spare_frames <= 8, "spare_frames must be in [0, 8]");
  Require(max_clock_drift >= 0.0 && max_clock_drift < 0.1, "max_clock_drift must be in [0, 0.1)");
}

bool IsClean(const sync::FrameMap& map, int frame, double begin, double end, double margin) {
  const double start = map.ProjectorTime(frame);
  return start >= begin + margin && start + map.ProjectorExposure() <= end - margin;
}

std::vector<int> PickFrames(const sync::FrameMap& map, double begin, double end, double margin, double slack,
                            int count, int first_frame) {
  const double guard = margin + slack;
  // Exposure starts allowed in [begin + guard, end - guard - exposure].
  const int first = std::max(first_frame, static_cast<int>(std::ceil(map.CameraFrame(begin + guard) - 1e-9)));
  const int last = static_cast<int>(std::floor(map.CameraFrame(end - guard - map.ProjectorExposure()) + 1e-9));
  std::vector<int> clean;
  for (int frame = first; frame <= last; ++frame) clean.push_back(frame);
  const double centre = map.CameraFrame(0.5 * (begin + end) - 0.5 * map.ProjectorExposure());
  std::stable_sort(clean.begin(), clean.end(),
                   [&](int a, int b) { return std::abs(a - centre) < std::abs(b - centre); });
  if (static_cast<int>(clean.size()) > count) clean.resize(count);
  std::sort(clean.begin(), clean.end());
  return clean;
}

}  // namespace calibproj::video
