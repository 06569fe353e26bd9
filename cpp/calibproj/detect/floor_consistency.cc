#include "calibproj/detect/floor_consistency.h"

#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <numeric>
#include <set>
#include <stdexcept>
#include <string>

namespace calibproj::detect {

void ConsistencyOptions::Check() const {
  if (!(threshold_px > 0.0)) throw std::invalid_argument("consistency: threshold_px must be positive");
  if (min_points < 4) throw std::invalid_argument("consistency: min_points must be at least 4");
  if (!(min_share > 0.0 && min_share <= 1.0)) throw std::invalid_argument("consistency: min_share must be in (0, 1]");
  if (min_positions < 1) throw std::invalid_argument("consistency: min_positions must be at least 1");
  if (max_surfaces < 1 || max_surfaces > 100) throw std::invalid_argument("consistency: max_surfaces must be in [1, 100]");
}

namespace {

// The detections (among `candidates`) within threshold of a RANSAC homography of theirs;
// empty when none is found.
std::vector<int> AgreeingWithOneHomography(const std::vector<cv::Point2d>& projector,
                                           const std::vector<cv::Point2d>& image, const std::vector<int>& candidates,
                                           double threshold_px) {
  if (candidates.size() < 4) return {};
  std::vector<cv::Point2d> from, to;
  for (int i : candidates) {
    from.push_back(projector[i]);
    to.push_back(image[i]);
  }
  cv::Mat inliers;
  const cv::Mat H = cv::findHomography(from, to, cv::RANSAC, threshold_px, inliers, 5000, 0.9999);
  if (H.empty()) return {};
  const cv::Matx33d h(H);
  std::vector<int> agreeing;
  for (int i : candidates) {
    const cv::Vec3d p = h * cv::Vec3d(projector[i].x, projector[i].y, 1.0);
    if (p[2] != 0.0 && cv::norm(cv::Point2d(p[0] / p[2], p[1] / p[2]) - image[i]) <= threshold_px) {
      agreeing.push_back(i);
    }
  }
  return agreeing;
}

// How many distinct places the detections cover: marker positions (grid cells), or
// image points farther apart than `separation_px`, whichever count is larger.
int Places(const std::vector<int>& chosen, const std::vector<cv::Point2d>& image, const std::vector<int>& position,
           double separation_px) {
  std::set<int> positions;
  std::vector<cv::Point2d> spots;
  for (int i : chosen) {
    positions.insert(position[i]);
    bool near = false;
    for (const cv::Point2d& spot : spots) near = near || cv::norm(spot - image[i]) <= separation_px;
    if (!near) spots.push_back(image[i]);
  }
  return static_cast<int>(std::max(positions.size(), spots.size()));
}

}  // namespace

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
  const double separation_px = 4.0 * options.threshold_px;
  std::vector<int> all(n);
  std::iota(all.begin(), all.end(), 0);
  const std::vector<int> floor = AgreeingWithOneHomography(projector, image, all, options.threshold_px);
  const int agreeing = static_cast<int>(floor.size());
  if (agreeing < options.min_points || agreeing < options.min_share * n) {
    result.keep.assign(n, false);
    result.rejected = n;
    result.problem = "only " + std::to_string(agreeing) + " of " + std::to_string(n) +
                     " detections agree with one homography of the floor";
    return result;
  }
  const int places = Places(floor, image, position, separation_px);
  if (places < options.min_positions) {
    result.keep.assign(n, false);
    result.rejected = n;
    result.problem = "the " + std::to_string(agreeing) + " detections that agree with one homography of the floor " +
                     "cover " + std::to_string(places) + " marker position(s), too few to check (need " +
                     std::to_string(options.min_positions) + ")";
    return result;
  }
  result.keep.assign(n, false);
  for (int i : floor) result.keep[i] = true;
  // Other surfaces (a table top): more homographies among the detections left.
  for (int surface = 1; surface < options.max_surfaces; ++surface) {
    std::vector<int> rest;
    for (int i = 0; i < n; ++i) {
      if (!result.keep[i]) rest.push_back(i);
    }
    const std::vector<int> more = AgreeingWithOneHomography(projector, image, rest, options.threshold_px);
    if (static_cast<int>(more.size()) < options.min_points ||
        Places(more, image, position, separation_px) < options.min_positions) {
      break;
    }
    for (int i : more) result.keep[i] = true;
  }
  const int kept = static_cast<int>(std::count(result.keep.begin(), result.keep.end(), true));
  result.rejected = n - kept;
  return result;
}

}  // namespace calibproj::detect
