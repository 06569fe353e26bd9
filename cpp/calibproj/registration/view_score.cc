#include "calibproj/registration/view_score.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace calibproj::registration {

VisibilityPyramid::VisibilityPyramid(int levels, double width, double height)
    : levels_(levels), width_(width), height_(height) {
  if (levels < 1 || levels > 12) throw std::invalid_argument("view score: levels must be in [1, 12]");
  if (!(width > 0.0 && height > 0.0 && std::isfinite(width * height))) {
    throw std::invalid_argument("view score: image size must be positive and finite");
  }
  for (int level = 0; level < levels; ++level) {
    const int dim = 1 << (level + 1);
    counts_.emplace_back(dim * dim, 0);
  }
}

void VisibilityPyramid::Add(double x, double y) {
  if (!std::isfinite(x) || !std::isfinite(y)) throw std::invalid_argument("view score: non-finite pixel");
  for (int level = 0; level < levels_; ++level) {
    const int dim = 1 << (level + 1);
    const int col = std::clamp(static_cast<int>(std::floor(x / width_ * dim)), 0, dim - 1);
    const int row = std::clamp(static_cast<int>(std::floor(y / height_ * dim)), 0, dim - 1);
    if (counts_[level][row * dim + col]++ == 0) score_ += dim;
  }
}

int VisibilityPyramid::MaxScore() const {
  int total = 0;
  for (int level = 0; level < levels_; ++level) {
    const int dim = 1 << (level + 1);
    total += dim * dim * dim;
  }
  return total;
}

}  // namespace calibproj::registration
