#pragma once
// Mean luma of decoded grey frames (VideoReader::Gray) for synchronisation.

#include <opencv2/core.hpp>

#include <array>
#include <cstdint>
#include <vector>

namespace calibproj::video {

// Limited-range ("TV", 16 black, 235 white) luma to full range, rounded and clipped as
// FFmpeg's YUV to RGB conversion does.
std::uint8_t LimitedToFull(int value);

// A frame's 8-bit luma as decoded: the plane and whether it is limited range.
struct LumaPlane {
  cv::Mat image;
  bool limited_range = false;
};

// The full-range grey image of `luma`: a new image, stretched where it is limited range.
cv::Mat FullRangeGray(const LumaPlane& luma);

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

  // The same of a decoded luma plane, stretched to full range first where it is
  // limited range (the same values as Mean of the grey image VideoReader::Gray makes).
  double Mean(const LumaPlane& luma, std::vector<double>* bands) const;

 private:
  std::array<float, 256> linear_;          // full-range value -> linear
  std::array<float, 256> linear_limited_;  // limited-range value -> linear
  int row_step_;
};

}  // namespace calibproj::video
