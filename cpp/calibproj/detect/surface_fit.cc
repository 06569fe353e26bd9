#include "calibproj/detect/surface_fit.h"

#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <cmath>

namespace calibproj::detect {

cv::Point2d ApplyHomography(const cv::Matx33d& H, const cv::Point2d& p) {
  const cv::Vec3d q = H * cv::Vec3d(p.x, p.y, 1.0);
  return {q[0] / q[2], q[1] / q[2]};
}

SurfaceFit FitSurface(const std::vector<cv::Point2d>& projector, const std::vector<cv::Point2d>& image,
                      const std::vector<int>& chosen, const SurfaceFitOptions& options) {
  SurfaceFit fit;
  if (chosen.size() < 4) return fit;
  std::vector<cv::Point2d> from, to;
  for (int i : chosen) {
    from.push_back(projector[i]);
    to.push_back(image[i]);
  }
  std::vector<unsigned char> ransac_inlier;
  const cv::Mat H = cv::findHomography(from, to, cv::RANSAC, options.threshold_px, ransac_inlier,
                                       options.max_iterations, options.confidence);
  if (H.empty()) return fit;
  fit.H = cv::Matx33d(H);
  const double limit = options.threshold_px * options.threshold_px;
  double squares = 0.0;
  for (std::size_t k = 0; k < chosen.size(); ++k) {
    if (options.within_ransac_inliers && !ransac_inlier[k]) continue;
    const int i = chosen[k];
    const cv::Point2d predicted = ApplyHomography(fit.H, projector[i]);
    if (!std::isfinite(predicted.x) || !std::isfinite(predicted.y)) continue;
    const cv::Point2d d = predicted - image[i];
    if (d.dot(d) > limit) continue;
    squares += d.dot(d);
    fit.inliers.push_back(i);
  }
  fit.rms_px = std::sqrt(squares / std::max<std::size_t>(fit.inliers.size(), 1));
  return fit;
}

}  // namespace calibproj::detect
