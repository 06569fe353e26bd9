#include "calibproj/detect/floor_consistency.h"

#include <opencv2/flann.hpp>

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <set>
#include <stdexcept>
#include <string>

#include "calibproj/detect/surface_fit.h"

namespace calibproj::detect {

void ConsistencyOptions::Check() const {
  if (!(threshold_px > 0.0)) throw std::invalid_argument("consistency: threshold_px must be positive");
  if (min_points < 4) throw std::invalid_argument("consistency: min_points must be at least 4");
  if (!(min_share > 0.0 && min_share <= 1.0)) throw std::invalid_argument("consistency: min_share must be in (0, 1]");
  if (min_positions < 1) throw std::invalid_argument("consistency: min_positions must be at least 1");
  if (max_surfaces < 1 || max_surfaces > 100) throw std::invalid_argument("consistency: max_surfaces must be in [1, 100]");
  if (local_neighbours < 0 || local_neighbours > 64) {
    throw std::invalid_argument("consistency: local_neighbours must be in [0, 64]");
  }
  if (!(local_sigmas > 0.0)) throw std::invalid_argument("consistency: local_sigmas must be positive");
  if (!(min_local_px >= 0.0)) throw std::invalid_argument("consistency: min_local_px must be non-negative");
}

namespace {

// The detections (among `candidates`) within threshold of a RANSAC homography of theirs.
SurfaceFit AgreeingWithOneHomography(const std::vector<cv::Point2d>& projector,
                                     const std::vector<cv::Point2d>& image, const std::vector<int>& candidates,
                                     double threshold_px) {
  SurfaceFitOptions options;
  options.threshold_px = threshold_px;
  options.max_iterations = 5000;
  options.confidence = 0.9999;
  return FitSurface(projector, image, candidates, options);
}

// Median of each coordinate.
cv::Point2d CoordinateMedian(const std::vector<cv::Point2d>& points) {
  std::vector<double> xs, ys;
  for (const cv::Point2d& p : points) {
    xs.push_back(p.x);
    ys.push_back(p.y);
  }
  std::nth_element(xs.begin(), xs.begin() + xs.size() / 2, xs.end());
  std::nth_element(ys.begin(), ys.begin() + ys.size() / 2, ys.end());
  return {xs[xs.size() / 2], ys[ys.size() / 2]};
}

// The `count` nearest rows of `points` (N x 2, CV_32F) to each of its rows, as indices
// (N x count, CV_32S). A k-d tree for many points; an exhaustive search for few, and
// wherever the tree's search comes back short (it asserts on some sets with many
// coincident points, as the scales of one marker are).
cv::Mat NearestNeighbours(const cv::Mat& points, int count) {
  constexpr int kExhaustiveBelow = 2000;
  cv::Mat nearest, distances;
  if (points.rows >= kExhaustiveBelow) {
    try {
      cv::flann::Index tree(points, cv::flann::KDTreeIndexParams(4));
      tree.knnSearch(points, nearest, distances, count, cv::flann::SearchParams(128));
      return nearest;
    } catch (const cv::Exception&) {
      // Short: the exhaustive search below.
    }
  }
  cv::flann::Index exhaustive(points, cv::flann::LinearIndexParams());
  exhaustive.knnSearch(points, nearest, distances, count, cv::flann::SearchParams());
  return nearest;
}

// The local check of one surface's detections `members` (residual[i]: image minus the
// surface's prediction): how far each residual is from the median of its neighbours'
// (other markers; a lens known roughly leaves residuals that vary slowly over the image,
// while markers displaced by a table's edge or shadow come a few together, which a
// median of neighbours shrugs off better than a fit of them).
// Negative where too few neighbours are known.
std::vector<double> LocalDeviations(const std::vector<int>& members, const std::vector<cv::Point2d>& projector,
                                    const std::vector<cv::Point2d>& image, const std::vector<cv::Point2d>& residual,
                                    int neighbours) {
  std::vector<double> deviation(members.size(), -1.0);
  // The scales of one marker share its projector centre and count once: the neighbours
  // are markers, found from each marker's mean image position.
  std::map<std::pair<double, double>, int> marker_at;
  std::vector<std::vector<std::size_t>> detections;  // per marker, indices into members
  std::vector<cv::Point2d> sums;
  for (std::size_t k = 0; k < members.size(); ++k) {
    const cv::Point2d& p = projector[members[k]];
    const auto [it, added] = marker_at.try_emplace({p.x, p.y}, static_cast<int>(detections.size()));
    if (added) {
      detections.emplace_back();
      sums.emplace_back(0.0, 0.0);
    }
    detections[it->second].push_back(k);
    sums[it->second] += image[members[k]];
  }
  const int markers = static_cast<int>(detections.size());
  if (markers <= neighbours) return deviation;
  cv::Mat points(markers, 2, CV_32F);
  for (int m = 0; m < markers; ++m) {
    const cv::Point2d mean = sums[m] * (1.0 / static_cast<double>(detections[m].size()));
    points.at<float>(m, 0) = static_cast<float>(mean.x);
    points.at<float>(m, 1) = static_cast<float>(mean.y);
  }
  const cv::Mat nearest = NearestNeighbours(points, neighbours + 1);
  for (int m = 0; m < markers; ++m) {
    for (const std::size_t k : detections[m]) {
      const cv::Point2d& here = image[members[k]];
      std::vector<cv::Point2d> around;
      for (int j = 0; j <= neighbours && static_cast<int>(around.size()) < neighbours; ++j) {
        const int other = nearest.at<int>(m, j);
        if (other < 0 || other == m) continue;
        // That marker's detection nearest to this one.
        std::size_t closest = detections[other].front();
        for (const std::size_t candidate : detections[other]) {
          if (cv::norm(image[members[candidate]] - here) < cv::norm(image[members[closest]] - here)) {
            closest = candidate;
          }
        }
        around.push_back(residual[members[closest]]);
      }
      if (static_cast<int>(around.size()) == neighbours) {
        deviation[k] = cv::norm(residual[members[k]] - CoordinateMedian(around));
      }
    }
  }
  return deviation;
}

// Drops (in `keep`) the kept detections that stand out against their neighbours on
// their surface.
void RejectLocally(const std::vector<SurfaceFit>& surfaces, const std::vector<cv::Point2d>& projector,
                  const std::vector<cv::Point2d>& image, const ConsistencyOptions& options, std::vector<bool>* keep) {
  if (options.local_neighbours <= 0) return;
  std::vector<cv::Point2d> residual(image.size());
  std::vector<std::pair<int, double>> deviations;  // detection, deviation
  for (const SurfaceFit& surface : surfaces) {
    for (int i : surface.inliers) residual[i] = image[i] - ApplyHomography(surface.H, projector[i]);
    const std::vector<double> deviation =
        LocalDeviations(surface.inliers, projector, image, residual, options.local_neighbours);
    for (std::size_t k = 0; k < deviation.size(); ++k) {
      if (deviation[k] >= 0.0) deviations.emplace_back(surface.inliers[k], deviation[k]);
    }
  }
  if (deviations.empty()) return;
  std::vector<double> values;
  for (const auto& [i, value] : deviations) values.push_back(value);
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  // The distance of a 2D Gaussian error from its centre has median sigma sqrt(2 ln 2).
  const double sigma = values[values.size() / 2] / std::sqrt(2.0 * std::log(2.0));
  const double limit = std::max(options.min_local_px, options.local_sigmas * sigma);
  for (const auto& [i, value] : deviations) {
    if (value > limit) (*keep)[i] = false;
  }
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

// Too few detections for a homography: drops those that repeat at one image place
// (within threshold_px) for kStaticRepeats or more different projector centres. A
// projection moves from array to array, so three MSMs decoded at one spot are a static
// pattern of the room (a stain, a printed marker) read again in every array that shows
// its id. Returns how many were dropped.
constexpr int kStaticRepeats = 3;

int DropStaticRepeats(const std::vector<cv::Point2d>& projector, const std::vector<cv::Point2d>& image,
                      double threshold_px, std::vector<bool>* keep) {
  const int n = static_cast<int>(image.size());
  std::vector<bool> drop(n, false);
  for (int i = 0; i < n; ++i) {
    std::vector<cv::Point2d> centres;
    for (int j = 0; j < n; ++j) {
      if (cv::norm(image[j] - image[i]) > threshold_px) continue;
      bool seen = false;
      for (const cv::Point2d& c : centres) seen = seen || cv::norm(c - projector[j]) < 0.5;
      if (!seen) centres.push_back(projector[j]);
    }
    drop[i] = static_cast<int>(centres.size()) >= kStaticRepeats;
  }
  int dropped = 0;
  for (int i = 0; i < n; ++i) {
    if (drop[i]) {
      (*keep)[i] = false;
      ++dropped;
    }
  }
  return dropped;
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
  if (n < options.min_points) {
    result.rejected = DropStaticRepeats(projector, image, options.threshold_px, &result.keep);
    return result;
  }
  result.checked = true;
  cv::setRNGSeed(static_cast<int>(options.seed));
  const double separation_px = 4.0 * options.threshold_px;
  std::vector<int> all(n);
  std::iota(all.begin(), all.end(), 0);
  std::vector<SurfaceFit> surfaces = {AgreeingWithOneHomography(projector, image, all, options.threshold_px)};
  const std::vector<int> floor = surfaces[0].inliers;
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
    SurfaceFit more = AgreeingWithOneHomography(projector, image, rest, options.threshold_px);
    if (static_cast<int>(more.inliers.size()) < options.min_points ||
        Places(more.inliers, image, position, separation_px) < options.min_positions) {
      break;
    }
    for (int i : more.inliers) result.keep[i] = true;
    surfaces.push_back(std::move(more));
  }
  RejectLocally(surfaces, projector, image, options, &result.keep);
  const int kept = static_cast<int>(std::count(result.keep.begin(), result.keep.end(), true));
  result.rejected = n - kept;
  return result;
}

}  // namespace calibproj::detect
