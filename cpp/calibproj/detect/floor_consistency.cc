#include "calibproj/detect/floor_consistency.h"

#include <opencv2/calib3d.hpp>

#include <set>
#include <stdexcept>
#include <string>

namespace calibproj::detect {

void ConsistencyOptions::Check() const {
  if (!(threshold_px > 0.0)) throw std::invalid_argument("consistency: threshold_px must be positive");
  if (min_points < 4) throw std::invalid_argument("consistency: min_points must be at least 4");
  if (!(min_share > 0.0 && min_share <= 1.0)) throw std::invalid_argument("consistency: min_share must be in (0, 1]");
  if (min_positions < 1) throw std::invalid_argument("consistency: min_positions must be at least 1");
}

ConsistencyResult CheckFloorConsistency(const std::vector<cv::Point2d>& projector,
                                        const std::vector<cv::Point2d>& image, const std::vector<int>& position,
                                        const ConsistencyOptions& options) {
  options.Check();
  if (projector.size() != image.size() || position.size() != image.size()) {
    throw std::invalid_argument("consistency: point counts differ");
  }
  for (const auto* points : {&projector, &image}) {
    for (const cv::Point2d& p : *points) {
      if (!std::isfinite(p.x) || !std::isfinite(p.y)) throw std::invalid_argument("consistency: non-finite point");
    }
  }
  const int n = static_cast<int>(projector.size());
  ConsistencyResult result;
  result.keep.assign(n, true);
  if (n < options.min_points) return result;
  result.checked = true;
  cv::setRNGSeed(static_cast<int>(options.seed));
  cv::Mat inliers;
  const cv::Mat H = cv::findHomography(projector, image, cv::RANSAC, options.threshold_px, inliers, 5000, 0.9999);
  int agreeing = 0;
  if (!H.empty()) {
    const cv::Matx33d h(H);
    for (int i = 0; i < n; ++i) {
      const cv::Vec3d p = h * cv::Vec3d(projector[i].x, projector[i].y, 1.0);
      const bool close = p[2] != 0.0 && cv::norm(cv::Point2d(p[0] / p[2], p[1] / p[2]) - image[i]) <= options.threshold_px;
      result.keep[i] = close;
      agreeing += close ? 1 : 0;
    }
  }
  if (H.empty() || agreeing < options.min_points || agreeing < options.min_share * n) {
    result.keep.assign(n, false);
    result.rejected = n;
    result.problem = "only " + std::to_string(agreeing) + " of " + std::to_string(n) +
                     " detections agree with one homography of the floor";
    return result;
  }
  std::set<int> positions;
  for (int i = 0; i < n; ++i) {
    if (result.keep[i]) positions.insert(position[i]);
  }
  if (static_cast<int>(positions.size()) < options.min_positions) {
    result.keep.assign(n, false);
    result.rejected = n;
    result.problem = "the " + std::to_string(agreeing) + " detections that agree with one homography of the floor " +
                     "cover " + std::to_string(positions.size()) + " marker position(s), too few to check (need " +
                     std::to_string(options.min_positions) + ")";
    return result;
  }
  result.rejected = n - agreeing;
  return result;
}

}  // namespace calibproj::detect
