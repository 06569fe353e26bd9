#include "calibproj/video/luma.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "calibproj/common/limits.h"

namespace calibproj::video {

namespace {

double RowSumGray(const std::uint8_t* row, int width, const std::array<float, 256>& linear) {
  float sum = 0.0f;
  for (int x = 0; x < width; ++x) sum += linear[row[x]];
  return sum;
}

}  // namespace

LumaMeter::LumaMeter(double gamma, int row_step) : row_step_(row_step) {
  if (row_step < 1 || row_step > limits::kMaxImageSide) {
    throw std::invalid_argument("luma: row_step must be in [1, " + std::to_string(limits::kMaxImageSide) + "]");
  }
  if (!(gamma > 0.0) || !std::isfinite(gamma)) throw std::invalid_argument("luma: gamma must be positive");
  for (int value = 0; value < 256; ++value) linear_[value] = static_cast<float>(std::pow(value / 255.0, gamma));
}

double LumaMeter::Mean(const cv::Mat& image) const { return Mean(image, nullptr); }

double LumaMeter::Mean(const cv::Mat& image, std::vector<double>* bands) const {
  if (image.empty() || image.type() != CV_8UC1) {
    throw std::invalid_argument("luma: expected a non-empty 8-bit grey image");
  }
  const int band_count = bands == nullptr ? 0 : static_cast<int>(bands->size());
  std::vector<int> band_rows(band_count, 0);
  if (band_count > 0) std::fill(bands->begin(), bands->end(), 0.0);
  double sum = 0.0;
  int rows = 0;
  for (int y = 0; y < image.rows; y += row_step_, ++rows) {
    const std::uint8_t* row = image.ptr<std::uint8_t>(y);
    const double row_sum = RowSumGray(row, image.cols, linear_);
    sum += row_sum;
    if (band_count > 0) {
      const int band = static_cast<int>(static_cast<long long>(y) * band_count / image.rows);
      (*bands)[band] += row_sum;
      ++band_rows[band];
    }
  }
  for (int b = 0; b < band_count; ++b) {
    (*bands)[b] = band_rows[b] > 0 ? (*bands)[b] / (static_cast<double>(band_rows[b]) * image.cols)
                                   : std::numeric_limits<double>::quiet_NaN();
  }
  return sum / (static_cast<double>(rows) * image.cols);
}

}  // namespace calibproj::video
