#include "calibproj/detect/detections.h"

#include <algorithm>
#include <numeric>
#include <stdexcept>
#include <string>
#include <tuple>

namespace calibproj::detect {

void SortById(Detections* detections) {
  std::vector<std::size_t> order(detections->size());
  std::iota(order.begin(), order.end(), 0);
  const auto key = [&](std::size_t i) {
    const cv::Point2d& first = detections->corners[i][0];
    return std::make_tuple(detections->ids[i], first.y, first.x);
  };
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return key(a) < key(b); });
  Detections sorted;
  for (std::size_t i : order) {
    sorted.ids.push_back(detections->ids[i]);
    sorted.corners.push_back(detections->corners[i]);
  }
  *detections = std::move(sorted);
}

void CheckGrayImage(const cv::Mat& image) {
  if (image.empty()) throw std::invalid_argument("image is empty");
  if (image.dims != 2 || image.type() != CV_8UC1) {
    throw std::invalid_argument("expected an 8-bit single-channel image, got type " +
                                cv::typeToString(image.type()) + " with " + std::to_string(image.dims) +
                                " dimensions");
  }
  if (image.cols < kMinImageSide || image.rows < kMinImageSide) {
    throw std::invalid_argument("image of " + std::to_string(image.cols) + "x" + std::to_string(image.rows) +
                                " px is too small to hold a marker (need at least " +
                                std::to_string(kMinImageSide) + "x" + std::to_string(kMinImageSide) + ")");
  }
}

}  // namespace calibproj::detect
