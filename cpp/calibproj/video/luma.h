#pragma once
// Mean luma of decoded grey frames (VideoReader::Gray) for synchronisation.

#include <opencv2/core.hpp>

#include <array>
#include <vector>

namespace calibproj::video {

// Mean brightness of frames for synchronisation. Each pixel's luma is first linearised
// by the video's display gamma (value^gamma), so that a frame exposed across a light
// change measures the exposure-weighted mean of the two light levels (a mean of
// gamma-encoded values would not be linear in the exposure shares). gamma = 1 keeps
// the encoded values.
class LumaMeter {
 public:
  // Throws std::invalid_argument for row_step < 1 or gamma <= 0.
  LumaMeter(double gamma, int row_step);

  // Mean linearised luma over every row_step-th row of an 8-bit grey image (full
  // scale 1).
  double Mean(const cv::Mat& image) const;

  // The same, and in one pass the mean of each of bands->size() horizontal bands of
  // equal height (band b: rows [b h / B, (b + 1) h / B)), for the rolling-shutter
  // readout. An empty `bands` measures the mean only.
  double Mean(const cv::Mat& image, std::vector<double>* bands) const;

 private:
  std::array<float, 256> linear_;
  int row_step_;
};

}  // namespace calibproj::video
