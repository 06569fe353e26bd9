#include "calibproj/video/luma_signal.h"

#include "calibproj/video/luma.h"
#include "calibproj/video/video_reader.h"

namespace calibproj::video {

std::vector<double> ReadLumaSignal(const std::string& path, double gamma, int row_step) {
  const LumaMeter meter(gamma, row_step);
  VideoReader reader(path);
  std::vector<double> signal;
  while (reader.Grab()) signal.push_back(meter.Mean(reader.Gray()));
  return signal;
}

}  // namespace calibproj::video
