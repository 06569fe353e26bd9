#include "calibproj/video/luma.h"

#include <cmath>
#include <cstdint>
#include <stdexcept>

namespace calibproj::video {

namespace {

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
  if (image.empty() || image.type() != CV_8UC1) {
    throw std::invalid_argument("luma: expected a non-empty 8-bit grey image");
  }
  double sum = 0.0;
  int rows = 0;
  for (int y = 0; y < image.rows; y += row_step_, ++rows) {
    const std::uint8_t* row = image.ptr<std::uint8_t>(y);
    sum += RowSumGray(row, image.cols, linear_);
  }
  return sum / (static_cast<double>(rows) * image.cols);
}

}  // namespace calibproj::video
