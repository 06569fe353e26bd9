#include "calibproj/geometry/pnp.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace calibproj::geometry {

namespace {

// Moves the points' centroid to the origin and scales their RMS distance from it to 1,
// so that the solvers' tolerances do not depend on the reconstruction's arbitrary unit.
// Returns false when the points do not spread beyond rounding.
bool Normalise(std::vector<cv::Point3d>* points, cv::Point3d* centroid, double* scale) {
  cv::Point3d mean(0, 0, 0);
  for (const auto& p : *points) mean += p;
  mean *= 1.0 / static_cast<double>(points->size());
  double variance = 0.0, size = 0.0;
  for (const auto& p : *points) {
    variance += (p - mean).dot(p - mean);
    size = std::max(size, std::abs(p.x) + std::abs(p.y) + std::abs(p.z));
  }
  variance /= static_cast<double>(points->size());
  if (!(variance > 1e-12 * std::max(1.0, size * size))) return false;
  *centroid = mean;
  *scale = std::sqrt(variance);
  for (auto& p : *points) p = (p - mean) * (1.0 / *scale);
  return true;
}

}  // namespace

PnpEstimate EstimatePoseRansac(const Points3& X, const Points2& pixels, const Eigen::Matrix3d& K,
                               const PnpOptions& options) {
  if (X.rows() != pixels.rows()) throw std::invalid_argument("pnp: point counts differ");
  PnpEstimate estimate;
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
  std::vector<int> rows;  // of X, per correspondence kept
  for (int i = 0; i < X.rows(); ++i) {
    if (!X.row(i).allFinite() || !pixels.row(i).allFinite()) continue;
    object.emplace_back(X(i, 0), X(i, 1), X(i, 2));
    image.emplace_back(pixels(i, 0), pixels(i, 1));
    rows.push_back(i);
  }
  if (static_cast<int>(object.size()) < std::max(options.min_inliers, 4)) return estimate;
  cv::Point3d centroid;
  double scale = 1.0;
  if (!Normalise(&object, &centroid, &scale)) {
    estimate.problem = "its " + std::to_string(object.size()) + " points lie at one place";
    return estimate;
  }
  cv::Mat K_cv;
  cv::eigen2cv(K, K_cv);
  cv::Mat rvec, tvec;
  std::vector<int> inliers;
  bool found = false;
  // SQPnP rejects samples whose normalised image points barely spread (a distant camera
  // seeing a small patch of floor): EPnP then.
  for (const int method : {cv::SOLVEPNP_SQPNP, cv::SOLVEPNP_EPNP}) {
    try {
      inliers.clear();
      found = cv::solvePnPRansac(object, image, K_cv, cv::noArray(), rvec, tvec, false, options.max_iterations,
                                 static_cast<float>(options.threshold_px), options.confidence, inliers, method);
      estimate.problem.clear();
      break;
    } catch (const cv::Exception& error) {
      estimate.problem = std::string("OpenCV: ") + error.err;
    }
  }
  if (!estimate.problem.empty()) return estimate;
  if (!found || static_cast<int>(inliers.size()) < options.min_inliers) {
    for (int& i : inliers) i = rows[i];
    estimate.inliers = inliers;
    return estimate;
  }
  std::vector<cv::Point3d> inlier_object;
  std::vector<cv::Point2d> inlier_image;
  for (int i : inliers) {
    inlier_object.push_back(object[i]);
    inlier_image.push_back(image[i]);
  }
  cv::solvePnPRefineLM(inlier_object, inlier_image, K_cv, cv::noArray(), rvec, tvec);
  cv::Mat R_cv;
  cv::Rodrigues(rvec, R_cv);
  cv::cv2eigen(R_cv, estimate.R);
  Eigen::Vector3d t_normalised;
  cv::cv2eigen(tvec, t_normalised);
  // x ~ R (X - c) / s + t'  =>  t = s t' - R c.
  estimate.t = scale * t_normalised - estimate.R * Eigen::Vector3d(centroid.x, centroid.y, centroid.z);
  for (int& i : inliers) i = rows[i];
  estimate.inliers = std::move(inliers);
  estimate.success = estimate.R.allFinite() && estimate.t.allFinite();
  return estimate;
}

}  // namespace calibproj::geometry
