#include "calibproj/geometry/pnp.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <stdexcept>

namespace calibproj::geometry {

PnpEstimate EstimatePoseRansac(const Points3& X, const Points2& pixels, const Eigen::Matrix3d& K,
                               const PnpOptions& options) {
  if (X.rows() != pixels.rows()) throw std::invalid_argument("pnp: point counts differ");
  PnpEstimate estimate;
  if (X.rows() < std::max(options.min_inliers, 4)) return estimate;
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
  for (int i = 0; i < X.rows(); ++i) {
    object.emplace_back(X(i, 0), X(i, 1), X(i, 2));
    image.emplace_back(pixels(i, 0), pixels(i, 1));
  }
  cv::Mat K_cv;
  cv::eigen2cv(K, K_cv);
  cv::Mat rvec, tvec;
  std::vector<int> inliers;
  const bool found = cv::solvePnPRansac(object, image, K_cv, cv::noArray(), rvec, tvec, false, options.max_iterations,
                                        static_cast<float>(options.threshold_px), options.confidence, inliers,
                                        cv::SOLVEPNP_SQPNP);
  if (!found || static_cast<int>(inliers.size()) < options.min_inliers) {
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
  cv::cv2eigen(tvec, estimate.t);
  estimate.inliers = std::move(inliers);
  estimate.success = estimate.R.allFinite() && estimate.t.allFinite();
  return estimate;
}

}  // namespace calibproj::geometry
