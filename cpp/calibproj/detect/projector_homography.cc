#include "calibproj/detect/projector_homography.h"


#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>

namespace calibproj::detect {

namespace {

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument("homography options: " + message);
}

// Square root of the smaller eigenvalue of the points' covariance.
double Spread(const std::vector<cv::Point2d>& points) {
  cv::Point2d mean(0, 0);
  for (const auto& p : points) mean += p;
  mean *= 1.0 / static_cast<double>(points.size());
  double xx = 0, xy = 0, yy = 0;
  for (const auto& p : points) {
    const cv::Point2d d = p - mean;
    xx += d.x * d.x;
    xy += d.x * d.y;
    yy += d.y * d.y;
  }
  const double n = static_cast<double>(points.size());
  xx /= n, xy /= n, yy /= n;
  const double half_trace = 0.5 * (xx + yy);
  const double root = std::sqrt(std::max(0.0, half_trace * half_trace - (xx * yy - xy * xy)));
  return std::sqrt(std::max(0.0, half_trace - root));
}

SurfaceFitOptions FitOptions(const HomographyOptions& options) {
  SurfaceFitOptions fit;
  fit.threshold_px = options.ransac_threshold_px;
  fit.within_ransac_inliers = true;
  return fit;
}

std::vector<int> Without(const std::vector<int>& from, const std::vector<int>& removed) {
  std::vector<int> rest;
  std::set_difference(from.begin(), from.end(), removed.begin(), removed.end(), std::back_inserter(rest));
  return rest;
}

// Scale of H at p: the square root of its Jacobian's determinant (0 where it folds).
double LocalScale(const cv::Matx33d& H, const cv::Point2d& p) {
  const double w = H(2, 0) * p.x + H(2, 1) * p.y + H(2, 2);
  const cv::Point2d mapped = ApplyHomography(H, p);
  const double a = (H(0, 0) - mapped.x * H(2, 0)) / w, b = (H(0, 1) - mapped.x * H(2, 1)) / w;
  const double c = (H(1, 0) - mapped.y * H(2, 0)) / w, d = (H(1, 1) - mapped.y * H(2, 1)) / w;
  const double determinant = std::abs(a * d - b * c);
  return std::isfinite(determinant) ? std::sqrt(determinant) : 0.0;
}

std::vector<int> Union(const std::vector<int>& a, const std::vector<int>& b) {
  std::vector<int> both;
  std::set_union(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(both));
  return both;
}

// The points among `chosen` (ascending) that H maps within threshold_px of their image.
std::vector<int> Explained(const cv::Matx33d& H, const std::vector<cv::Point2d>& projector,
                           const std::vector<cv::Point2d>& image, const std::vector<int>& chosen, double threshold_px) {
  std::vector<int> explained;
  for (int i : chosen) {
    const cv::Point2d d = ApplyHomography(H, projector[i]) - image[i];
    if (d.dot(d) <= threshold_px * threshold_px) explained.push_back(i);
  }
  return explained;
}

// True unless the image points lie along a line (one row of markers on a table's edge
// fits many homographies): their spread across is at least a tenth of that along.
bool Extended(const std::vector<cv::Point2d>& image, const std::vector<int>& chosen) {
  std::vector<cv::Point2d> points;
  for (int i : chosen) points.push_back(image[i]);
  const double across = Spread(points);
  cv::Point2d mean(0, 0);
  for (const auto& p : points) mean += p;
  mean *= 1.0 / static_cast<double>(points.size());
  double total = 0.0;
  for (const auto& p : points) total += (p - mean).dot(p - mean);
  const double along = std::sqrt(std::max(0.0, total / points.size() - across * across));
  return across >= 0.1 * along && across > 0.0;
}

struct FurtherSurfaces {
  std::vector<SurfaceFit> surfaces;
  int unexplained = 0;  // correspondences no surface explains
};

// Surfaces besides the dominant one among the correspondences it leaves (`rest`), the
// largest first. Points along a line (one row of a table's markers found so far) agree
// with many homographies: they count as explained, but plan nothing until the rest of
// their surface is found.
FurtherSurfaces FitFurtherSurfaces(const std::vector<cv::Point2d>& projector, const std::vector<cv::Point2d>& image,
                                   std::vector<int> rest, const HomographyOptions& options) {
  FurtherSurfaces further;
  further.unexplained = static_cast<int>(rest.size());
  for (int attempt = 0; attempt < 2 * options.max_surfaces; ++attempt) {
    if (static_cast<int>(further.surfaces.size()) + 1 >= options.max_surfaces) break;
    if (static_cast<int>(rest.size()) < options.min_points) break;
    SurfaceFit surface = FitSurface(projector, image, rest, FitOptions(options));
    if (static_cast<int>(surface.inliers.size()) < options.min_points || surface.rms_px > options.max_rms_px) break;
    rest = Without(rest, surface.inliers);
    further.unexplained -= static_cast<int>(surface.inliers.size());
    if (Extended(image, surface.inliers)) further.surfaces.push_back(std::move(surface));
  }
  return further;
}

}  // namespace

void HomographyOptions::Check() const {
  Require(min_points >= 4, "min_points must be at least 4");
  Require(min_spread >= 0.0, "min_spread must be non-negative");
  Require(ransac_threshold_px > 0.0, "ransac_threshold_px must be positive");
  Require(min_inlier_share > 0.0 && min_inlier_share <= 1.0, "min_inlier_share must be in (0, 1]");
  Require(max_rms_px > 0.0, "max_rms_px must be positive");
  Require(max_scale_ratio >= 1.0, "max_scale_ratio must be at least 1");
  Require(max_surfaces >= 1 && max_surfaces <= 100, "max_surfaces must be in [1, 100]");
}

ProjectorHomography::ProjectorHomography(cv::Size image_size, HomographyOptions options)
    : image_size_(image_size), options_(options) {
  options_.Check();
}

void ProjectorHomography::Add(const cv::Point2d& projector, const cv::Point2d& image, double scale) {
  ImageSum& point = points_[{projector.x, projector.y}];
  point.sum += image;
  ++point.count;
  if (scale > 0.0 && std::isfinite(scale)) {
    point.scale_sum += scale;
    ++point.scales;
  }
}

bool ProjectorHomography::ScaleAgrees(const cv::Matx33d& H, const std::vector<cv::Point2d>& projector,
                                      const std::vector<double>& scales, const std::vector<int>& chosen) const {
  std::vector<double> ratios;
  for (int i : chosen) {
    if (scales[i] > 0.0) ratios.push_back(LocalScale(H, projector[i]) / scales[i]);
  }
  if (ratios.empty()) return true;
  std::nth_element(ratios.begin(), ratios.begin() + ratios.size() / 2, ratios.end());
  const double median = ratios[ratios.size() / 2];
  return median * options_.max_scale_ratio >= 1.0 && median <= options_.max_scale_ratio;
}

bool ProjectorHomography::Update() {
  const int count = point_count();
  // Refit while few points are known, then whenever their number grew by a quarter.
  const bool due = !valid_ ? count > fitted_count_ : count >= fitted_count_ + std::max(4, fitted_count_ / 4);
  if (count >= options_.min_points && due) {
    fitted_count_ = count;
    const bool fitted = Fit();
    valid_ = valid_ || fitted;
  }
  return valid_;
}

bool ProjectorHomography::Refit() {
  if (point_count() >= options_.min_points) {
    fitted_count_ = point_count();
    valid_ = Fit() || valid_;
  }
  return valid_;
}

bool ProjectorHomography::CrossesSurfaces(const cv::Point2d& centre, double side) const {
  if (surface_count() < 2) return false;
  const int surface = SurfaceIndexAt(centre);
  const double h = 0.5 * side;
  for (const cv::Point2d corner : {centre + cv::Point2d(-h, -h), centre + cv::Point2d(h, -h),
                                   centre + cv::Point2d(h, h), centre + cv::Point2d(-h, h)}) {
    if (SurfaceIndexAt(corner) != surface) return true;
  }
  return false;
}

bool ProjectorHomography::Fit() {
  std::vector<cv::Point2d> projector, image;
  std::vector<double> scales;  // 0: unknown
  for (const auto& [key, point] : points_) {
    projector.emplace_back(key.first, key.second);
    image.push_back(point.sum * (1.0 / point.count));
    scales.push_back(point.scales > 0 ? point.scale_sum / point.scales : 0.0);
  }
  const double diagonal = std::hypot(image_size_.width, image_size_.height);
  if (Spread(image) < options_.min_spread * diagonal) return false;
  std::vector<int> all(projector.size());
  std::iota(all.begin(), all.end(), 0);
  SurfaceFit dominant = FitSurface(projector, image, all, FitOptions(options_));
  if (dominant.inliers.empty() || dominant.rms_px > options_.max_rms_px) return false;
  if (!ScaleAgrees(dominant.H, projector, scales, dominant.inliers)) return false;
  // Points the dominant surface's refined model explains are its own too: RANSAC's model,
  // from four points, can leave a cluster of the floor's points beyond the threshold,
  // which would then be taken for a surface of their own (measured: one array of a near
  // camera). Its fit and RMS stay those of RANSAC's inliers.
  dominant.inliers =
      Union(dominant.inliers, Explained(dominant.H, projector, image, all, options_.ransac_threshold_px));
  const FurtherSurfaces further = FitFurtherSurfaces(projector, image, Without(all, dominant.inliers), options_);
  // Another surface's points are not outliers of the dominant one: the share is of all
  // the points some surface explains.
  const int explained = static_cast<int>(projector.size()) - further.unexplained;
  if (explained < options_.min_inlier_share * point_count()) return false;
  H_ = dominant.H;
  rms_px_ = dominant.rms_px;
  more_.clear();
  labelled_.clear();
  label_.clear();
  surface_cache_.clear();
  for (int i : dominant.inliers) {
    labelled_.push_back(projector[i]);
    label_.push_back(0);
  }
  for (std::size_t k = 0; k < further.surfaces.size(); ++k) {
    more_.push_back(further.surfaces[k].H);
    for (int i : further.surfaces[k].inliers) {
      labelled_.push_back(projector[i]);
      label_.push_back(static_cast<int>(k) + 1);
    }
  }
  return true;
}

int ProjectorHomography::SurfaceIndexAt(const cv::Point2d& projector) const {
  if (more_.empty()) return 0;
  const auto key = std::make_pair(projector.x, projector.y);
  auto cached = surface_cache_.find(key);
  if (cached == surface_cache_.end()) {
    int nearest = 0;
    double best = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < labelled_.size(); ++i) {
      const cv::Point2d d = labelled_[i] - projector;
      const double squared = d.dot(d);
      if (squared < best) {
        best = squared;
        nearest = label_[i];
      }
    }
    cached = surface_cache_.emplace(key, nearest).first;
  }
  return cached->second;
}

const cv::Matx33d& ProjectorHomography::SurfaceAt(const cv::Point2d& projector) const {
  const int surface = SurfaceIndexAt(projector);
  return surface == 0 ? H_ : more_[surface - 1];
}

cv::Point2d ProjectorHomography::Map(const cv::Point2d& projector) const { return ApplyHomography(H_, projector); }

}  // namespace calibproj::detect
