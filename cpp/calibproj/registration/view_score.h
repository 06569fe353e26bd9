#pragma once
// View score of COLMAP (Schoenberger & Frahm 2016, section 4.2), used by the paper to
// pick the initial pair and the next camera: a pyramid of occupancy grids over the
// image, 2x2, 4x4, ... cells; each cell that holds at least one observation adds its
// level's resolution (2, 4, ...) to the score, so many well-spread points score high.

#include <vector>

namespace calibproj::registration {

class VisibilityPyramid {
 public:
  VisibilityPyramid(int levels, double width, double height);
  void Add(double x, double y);
  int Score() const { return score_; }
  int MaxScore() const;

 private:
  int levels_;
  double width_, height_;
  std::vector<std::vector<int>> counts_;  // per level, row-major cells
  int score_ = 0;
};

}  // namespace calibproj::registration
