#pragma once
// What a marker detector returns for one image.

#include <opencv2/core.hpp>

#include <array>
#include <vector>

namespace calibproj::detect {

// Four corners in OpenCV's pixel convention (centre of the top-left pixel at (0, 0))
// and OpenCV's order: clockwise in the image starting at the marker's top-left
// corner as drawn (top-left, top-right, bottom-right, bottom-left).
using Quad = std::array<cv::Point2d, 4>;

struct Detections {
  std::vector<int> ids;
  std::vector<Quad> corners;  // corners[i] belongs to ids[i]

  std::size_t size() const { return ids.size(); }
};

// Orders detections by id (ties by the first corner), so results do not depend on
// the detector's internal order.
void SortById(Detections* detections);

// Throws std::invalid_argument unless `image` is a non-empty 2-D CV_8UC1 image of at
// least kMinImageSide pixels on each side.
constexpr int kMinImageSide = 8;
void CheckGrayImage(const cv::Mat& image);

}  // namespace calibproj::detect
