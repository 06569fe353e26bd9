#pragma once
// Grey images between numpy and OpenCV.

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <opencv2/core.hpp>

#include <algorithm>
#include <stdexcept>
#include <string>

namespace calibproj::bindings {

// A cv::Mat header over a 2-D uint8 numpy array (no copy; the array must outlive it).
inline cv::Mat GrayView(const pybind11::array& image) {
  if (image.dtype().kind() != 'u' || image.itemsize() != 1) {
    throw std::invalid_argument("expected an 8-bit (uint8) image, got dtype " +
                                std::string(pybind11::str(image.dtype())));
  }
  if (image.ndim() != 2) {
    throw std::invalid_argument("expected a 2-D grayscale image, got " + std::to_string(image.ndim()) +
                                " dimensions");
  }
  if (image.size() == 0) throw std::invalid_argument("image is empty");
  if (image.strides(1) != 1 || image.strides(0) < image.shape(1)) {
    throw std::invalid_argument("image rows must be contiguous (use numpy.ascontiguousarray)");
  }
  return cv::Mat(static_cast<int>(image.shape(0)), static_cast<int>(image.shape(1)), CV_8UC1,
                 const_cast<void*>(image.data()), static_cast<std::size_t>(image.strides(0)));
}

// A numpy copy of a CV_8UC1 image.
inline pybind11::array_t<uint8_t> GrayArray(const cv::Mat& image) {
  pybind11::array_t<uint8_t> out({static_cast<pybind11::ssize_t>(image.rows), static_cast<pybind11::ssize_t>(image.cols)});
  for (int row = 0; row < image.rows; ++row) {
    std::copy_n(image.ptr<uint8_t>(row), image.cols, out.mutable_data(row, 0));
  }
  return out;
}

}  // namespace calibproj::bindings
