#include "calibproj/detect/marker_verification.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace calibproj::detect {

namespace {

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument("marker verification options: " + message);
}

// Bilinear level of `gray` at `p`; false outside the pixel centres' hull.
bool Level(const cv::Mat& gray, const cv::Point2d& p, double* level) {
  if (!(p.x >= 0.0 && p.y >= 0.0 && p.x <= gray.cols - 1.0 && p.y <= gray.rows - 1.0)) return false;
  const int x = static_cast<int>(p.x), y = static_cast<int>(p.y);
  const int x1 = std::min(x + 1, gray.cols - 1), y1 = std::min(y + 1, gray.rows - 1);
  const double fx = p.x - x, fy = p.y - y;
  const uchar* row0 = gray.ptr<uchar>(y);
  const uchar* row1 = gray.ptr<uchar>(y1);
  const double top = row0[x] + fx * (row0[x1] - row0[x]);
  const double bottom = row1[x] + fx * (row1[x1] - row1[x]);
  *level = top + fy * (bottom - top);
  return true;
}

}  // namespace

cv::Mat ProjectedCells(const MarkerFamily& family, int id, bool inverted) {
  const cv::Mat bits = MarkerBits(family, id);
  return inverted ? cv::Mat((bits == 0) / 255) : bits.clone();
}

void VerificationOptions::Check() const {
  Require(min_contrast >= 0.0 && std::isfinite(min_contrast), "min_contrast must be non-negative");
  Require(samples >= 1 && samples <= 16, "samples must be in [1, 16]");
  Require(cell_share > 0.0 && cell_share <= 1.0, "cell_share must be in (0, 1]");
}

bool ShowsMarker(const cv::Mat& gray, const cv::Point& origin, const LensTables& lens, const Quad& undistorted,
                 const cv::Mat& bits, int quad_cells, const VerificationOptions& options) {
  if (bits.empty() || bits.type() != CV_8UC1 || bits.rows != bits.cols) {
    throw std::invalid_argument("marker verification: bits must be a square 8-bit grid");
  }
  if (gray.empty() || gray.type() != CV_8UC1) {
    throw std::invalid_argument("marker verification: expected an 8-bit image");
  }
  const int grid = bits.rows;
  if (quad_cells < 1 || quad_cells > grid) throw std::invalid_argument("marker verification: quad_cells out of range");
  const float side = static_cast<float>(quad_cells);
  const cv::Point2f square[4] = {{0.0f, 0.0f}, {side, 0.0f}, {side, side}, {0.0f, side}};
  cv::Point2f quad[4];
  for (int k = 0; k < 4; ++k) quad[k] = cv::Point2f(undistorted[k]);
  const cv::Matx33d H = cv::getPerspectiveTransform(square, quad);
  // Cell (row, column) spans [column - offset, column + 1 - offset] in quad modules.
  const double offset = 0.5 * (grid - quad_cells);
  const int n = options.samples;
  std::vector<cv::Point2d> points;
  points.reserve(static_cast<std::size_t>(grid * grid * n * n));
  for (int row = 0; row < grid; ++row) {
    for (int column = 0; column < grid; ++column) {
      for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) {
          const double u = column - offset + 0.5 + options.cell_share * ((j + 0.5) / n - 0.5);
          const double v = row - offset + 0.5 + options.cell_share * ((i + 0.5) / n - 0.5);
          const cv::Vec3d p = H * cv::Vec3d(u, v, 1.0);
          points.emplace_back(p[0] / p[2], p[1] / p[2]);
        }
      }
    }
  }
  const std::vector<cv::Point2d> image = lens.Distort(points);
  std::vector<double> cells(static_cast<std::size_t>(grid * grid), 0.0);
  for (std::size_t k = 0; k < image.size(); ++k) {
    double level = 0.0;
    if (!Level(gray, image[k] - cv::Point2d(origin.x, origin.y), &level)) return false;
    cells[k / static_cast<std::size_t>(n * n)] += level / (n * n);
  }
  double white = 0.0, black = 0.0;
  int whites = 0, blacks = 0;
  for (int k = 0; k < grid * grid; ++k) {
    if (bits.data[k] != 0) {
      white += cells[k];
      ++whites;
    } else {
      black += cells[k];
      ++blacks;
    }
  }
  if (whites == 0 || blacks == 0) return false;
  white /= whites;
  black /= blacks;
  if (!(white - black >= options.min_contrast)) return false;
  const double middle = 0.5 * (white + black);
  for (int k = 0; k < grid * grid; ++k) {
    if ((bits.data[k] != 0) != (cells[k] > middle)) return false;
  }
  return true;
}

}  // namespace calibproj::detect
