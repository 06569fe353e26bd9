#include "calibproj/video/luma_signal.h"

#include <limits>

#include "calibproj/video/frame_clock.h"
#include "calibproj/video/luma.h"
#include "calibproj/video/video_reader.h"

namespace calibproj::video {

std::vector<double> ReadLumaSignal(const std::string& path, double gamma, int row_step, bool use_timestamps,
                                   double max_gap_s) {
  const LumaMeter meter(gamma, row_step);
  VideoReader reader(path);
  FrameClock clock(1.0 / reader.info().fps, max_gap_s, use_timestamps, path);
  std::vector<double> signal;
  while (reader.Grab()) {
    const int slot = clock.Place(reader.timestamp());
    if (slot < 0) continue;
    signal.resize(slot, std::numeric_limits<double>::quiet_NaN());
    signal.push_back(meter.Mean(reader.Luma(), nullptr));
  }
  return signal;
}

std::vector<double> ReadFrameTimestamps(const std::string& path) {
  VideoReader reader(path);
  std::vector<double> times;
  while (reader.Grab()) times.push_back(reader.timestamp());
  return times;
}

}  // namespace calibproj::video
