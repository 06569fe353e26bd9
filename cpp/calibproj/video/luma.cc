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

// Four partial sums: one sum waits for each addition's latency, four keep the core busy.
double RowSumGray(const std::uint8_t* row, int width, const std::array<float, 256>& linear) {
  float sums[4] = {0.0f, 0.0f, 0.0f, 0.0f};
  int x = 0;
  for (; x + 4 <= width; x += 4) {
    sums[0] += linear[row[x]];
    sums[1] += linear[row[x + 1]];
    sums[2] += linear[row[x + 2]];
    sums[3] += linear[row[x + 3]];
  }
  for (; x < width; ++x) sums[0] += linear[row[x]];
  return (static_cast<double>(sums[0]) + sums[1]) + (static_cast<double>(sums[2]) + sums[3]);
}

double MeanOf(const cv::Mat& image, const std::array<float, 256>& linear, int row_step,
              std::vector<double>* bands) {
  if (image.empty() || image.type() != CV_8UC1) {
    throw std::invalid_argument("luma: expected a non-empty 8-bit grey image");
  }
  const int band_count = bands == nullptr ? 0 : static_cast<int>(bands->size());
  std::vector<int> band_rows(band_count, 0);
  if (band_count > 0) std::fill(bands->begin(), bands->end(), 0.0);
  double sum = 0.0;
  int rows = 0;
  for (int y = 0; y < image.rows; y += row_step, ++rows) {
    const std::uint8_t* row = image.ptr<std::uint8_t>(y);
    const double row_sum = RowSumGray(row, image.cols, linear);
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

}  // namespace

std::uint8_t LimitedToFull(int value) { return cv::saturate_cast<std::uint8_t>((value - 16) * 255.0 / 219.0); }

cv::Mat FullRangeGray(const LumaPlane& luma) {
  cv::Mat gray;
  if (!luma.limited_range) {
    luma.image.copyTo(gray);
    return gray;
  }
  // LimitedToFull as one scaling, which OpenCV vectorises (a table lookup is done a
  // byte at a time). The same values: (v - 16) * 255 / 219 is never within 1/438 of a
  // half, far beyond float's rounding.
  luma.image.convertTo(gray, CV_8U, 255.0 / 219.0, -16.0 * 255.0 / 219.0);
  return gray;
}

LumaMeter::LumaMeter(double gamma, int row_step) : row_step_(row_step) {
  if (row_step < 1 || row_step > limits::kMaxImageSide) {
    throw std::invalid_argument("luma: row_step must be in [1, " + std::to_string(limits::kMaxImageSide) + "]");
  }
  if (!(gamma > 0.0) || !std::isfinite(gamma)) throw std::invalid_argument("luma: gamma must be positive");
  for (int value = 0; value < 256; ++value) linear_[value] = static_cast<float>(std::pow(value / 255.0, gamma));
  for (int value = 0; value < 256; ++value) linear_limited_[value] = linear_[LimitedToFull(value)];
}

double LumaMeter::Mean(const cv::Mat& image) const { return Mean(image, nullptr); }

double LumaMeter::Mean(const cv::Mat& image, std::vector<double>* bands) const {
  return MeanOf(image, linear_, row_step_, bands);
}

double LumaMeter::Mean(const LumaPlane& luma, std::vector<double>* bands) const {
  return MeanOf(luma.image, luma.limited_range ? linear_limited_ : linear_, row_step_, bands);
}

}  // namespace calibproj::video
