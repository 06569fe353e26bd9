#include "calibproj/video/luma.h"

#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdint>
#include <stdexcept>

namespace calibproj::video {

namespace {

// cv::cvtColor(BGR2GRAY) for 8-bit images: fixed point with 14 fractional bits.
constexpr int kShift = 14;
constexpr int kBlue = 1868, kGreen = 9617, kRed = 4899;
constexpr int kHalf = 1 << (kShift - 1);

double RowSumBgr(const std::uint8_t* row, int width, const std::array<float, 256>& linear) {
  float sum = 0.0f;
  for (int x = 0; x < width; ++x, row += 3) {
    sum += linear[(row[0] * kBlue + row[1] * kGreen + row[2] * kRed + kHalf) >> kShift];
  }
  return sum;
}

double RowSumGray(const std::uint8_t* row, int width, const std::array<float, 256>& linear) {
  float sum = 0.0f;
  for (int x = 0; x < width; ++x) sum += linear[row[x]];
  return sum;
}

}  // namespace

LumaMeter::LumaMeter(double gamma, int row_step) : row_step_(row_step) {
  if (row_step < 1) throw std::invalid_argument("luma: row_step must be at least 1");
  if (!(gamma > 0.0)) throw std::invalid_argument("luma: gamma must be positive");
  for (int value = 0; value < 256; ++value) linear_[value] = static_cast<float>(std::pow(value / 255.0, gamma));
}

double LumaMeter::Mean(const cv::Mat& image) const {
  if (image.empty() || image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3)) {
    throw std::invalid_argument("luma: expected a non-empty 8-bit grey or BGR image");
  }
  double sum = 0.0;
  int rows = 0;
  for (int y = 0; y < image.rows; y += row_step_, ++rows) {
    const std::uint8_t* row = image.ptr<std::uint8_t>(y);
    sum += image.channels() == 3 ? RowSumBgr(row, image.cols, linear_) : RowSumGray(row, image.cols, linear_);
  }
  return sum / (static_cast<double>(rows) * image.cols);
}

cv::Mat GrayRegion(const cv::Mat& image, const cv::Rect& region) {
  const cv::Mat part = image(region);
  if (image.channels() == 1) return part.clone();
  cv::Mat gray;
  cv::cvtColor(part, gray, cv::COLOR_BGR2GRAY);
  return gray;
}

}  // namespace calibproj::video
