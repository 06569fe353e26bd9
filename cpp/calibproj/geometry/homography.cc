#include "calibproj/geometry/homography.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <random>
#include <stdexcept>

#include "calibproj/common/limits.h"

namespace calibproj::geometry {

namespace {

// Hartley normalisation: centroid at the origin, mean distance sqrt(2).
Eigen::Matrix3d NormalisingTransform(const Points2& x, const std::vector<int>& subset) {
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (int i : subset) mean += x.row(i).transpose();
  mean /= static_cast<double>(subset.size());
  double spread = 0.0;
  for (int i : subset) spread += (x.row(i).transpose() - mean).norm();
  spread = std::max(spread / static_cast<double>(subset.size()), 1e-12);
  const double s = std::sqrt(2.0) / spread;
  Eigen::Matrix3d T;
  T << s, 0, -s * mean.x(), 0, s, -s * mean.y(), 0, 0, 1;
  return T;
}

// Direct linear transform on the given correspondences (at least 4).
bool FitHomography(const Points2& x1, const Points2& x2, const std::vector<int>& subset, Eigen::Matrix3d* H) {
  const Eigen::Matrix3d T1 = NormalisingTransform(x1, subset);
  const Eigen::Matrix3d T2 = NormalisingTransform(x2, subset);
  Eigen::MatrixXd A(2 * subset.size(), 9);
  for (size_t k = 0; k < subset.size(); ++k) {
    const Eigen::Vector3d p = T1 * x1.row(subset[k]).transpose().homogeneous();
    const Eigen::Vector3d q = T2 * x2.row(subset[k]).transpose().homogeneous();
    A.row(2 * k) << 0, 0, 0, -p.transpose(), q.y() * p.transpose();
    A.row(2 * k + 1) << p.transpose(), 0, 0, 0, -q.x() * p.transpose();
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullV);
  const Eigen::VectorXd h = svd.matrixV().col(8);
  Eigen::Matrix3d Hn;
  Hn << h(0), h(1), h(2), h(3), h(4), h(5), h(6), h(7), h(8);
  *H = T2.inverse() * Hn * T1;
  if (!H->allFinite() || std::abs(H->determinant()) < 1e-15) return false;
  *H /= H->norm();
  return true;
}

// Largest of the two transfer errors, each in its own camera's pixels.
double SymmetricErrorPx(const Eigen::Matrix3d& H, const Eigen::Matrix3d& H_inv, const Eigen::Vector2d& p1,
                        const Eigen::Vector2d& p2, double focal1, double focal2) {
  const Eigen::Vector3d forward = H * p1.homogeneous();
  const Eigen::Vector3d backward = H_inv * p2.homogeneous();
  if (forward.z() == 0.0 || backward.z() == 0.0) return std::numeric_limits<double>::infinity();
  const double e2 = focal2 * (forward.hnormalized() - p2).norm();
  const double e1 = focal1 * (backward.hnormalized() - p1).norm();
  return std::max(e1, e2);
}

std::vector<int> Inliers(const Eigen::Matrix3d& H, const Points2& x1, const Points2& x2,
                         const HomographyRansacOptions& options) {
  std::vector<int> inliers;
  const Eigen::Matrix3d H_inv = H.inverse();
  for (int i = 0; i < x1.rows(); ++i) {
    const double error = SymmetricErrorPx(H, H_inv, x1.row(i).transpose(), x2.row(i).transpose(), options.focal1,
                                          options.focal2);
    if (error < options.threshold_px) inliers.push_back(i);
  }
  return inliers;
}

int RequiredIterations(int inliers, int total, double confidence, int max_iterations) {
  const double ratio = static_cast<double>(inliers) / total;
  const double p_good_sample = std::pow(ratio, 4);
  if (p_good_sample >= 1.0) return 1;
  if (p_good_sample <= 0.0) return max_iterations;
  const double needed = std::log(1.0 - confidence) / std::log(1.0 - p_good_sample);
  return static_cast<int>(std::min<double>(max_iterations, std::ceil(needed)));
}

}  // namespace

HomographyEstimate EstimateHomographyRansac(const Points2& x1, const Points2& x2,
                                            const HomographyRansacOptions& options) {
  if (x1.rows() != x2.rows()) throw std::invalid_argument("homography: point counts differ");
  if (!x1.allFinite() || !x2.allFinite()) throw std::invalid_argument("homography: non-finite point");
  limits::RequireInRange(options.max_iterations, 1, limits::kMaxIterations, "homography: max_iterations");
  limits::RequireInRange(options.confidence, 0.0, 1.0, "homography: confidence");
  limits::RequireFinite(options.threshold_px, "homography: threshold_px");
  if (!(options.focal1 > 0.0 && options.focal2 > 0.0 && std::isfinite(options.focal1 * options.focal2))) {
    throw std::invalid_argument("homography: focal lengths must be positive and finite");
  }
  HomographyEstimate best;
  const int n = static_cast<int>(x1.rows());
  if (n < 4) return best;
  std::mt19937_64 rng(options.seed);
  std::vector<int> all(n);
  std::iota(all.begin(), all.end(), 0);
  int iterations = options.max_iterations;
  for (int it = 0; it < iterations; ++it) {
    std::vector<int> sample(4);
    std::sample(all.begin(), all.end(), sample.begin(), 4, rng);
    Eigen::Matrix3d H;
    if (!FitHomography(x1, x2, sample, &H)) continue;
    std::vector<int> inliers = Inliers(H, x1, x2, options);
    if (inliers.size() > best.inliers.size()) {
      best.H = H;
      best.inliers = std::move(inliers);
      iterations = std::min(iterations, RequiredIterations(static_cast<int>(best.inliers.size()), n,
                                                           options.confidence, options.max_iterations));
    }
  }
  if (best.inliers.size() < 4) return HomographyEstimate{};
  // Refit on all inliers until the inlier set stops changing.
  for (int round = 0; round < 5; ++round) {
    Eigen::Matrix3d H;
    if (!FitHomography(x1, x2, best.inliers, &H)) break;
    std::vector<int> inliers = Inliers(H, x1, x2, options);
    if (inliers.size() < best.inliers.size()) break;
    const bool same = inliers == best.inliers;
    best.H = H;
    best.inliers = std::move(inliers);
    if (same) break;
  }
  best.success = true;
  return best;
}

std::vector<PlanarMotion> DecomposeHomography(const Eigen::Matrix3d& H, const Points2& x1, const Points2& x2) {
  // OpenCV's visibility filter reads one point of each set per point of the first.
  if (x1.rows() != x2.rows()) throw std::invalid_argument("homography decomposition: point counts differ");
  if (x1.rows() == 0) throw std::invalid_argument("homography decomposition: no points");
  if (!H.allFinite() || !x1.allFinite() || !x2.allFinite()) {
    throw std::invalid_argument("homography decomposition: non-finite H or points");
  }
  cv::Mat H_cv;
  cv::eigen2cv(H, H_cv);
  std::vector<cv::Mat> rotations, translations, normals;
  cv::decomposeHomographyMat(H_cv, cv::Mat::eye(3, 3, CV_64F), rotations, translations, normals);
  std::vector<cv::Point2f> before, after;
  for (int i = 0; i < x1.rows(); ++i) {
    before.emplace_back(static_cast<float>(x1(i, 0)), static_cast<float>(x1(i, 1)));
    after.emplace_back(static_cast<float>(x2(i, 0)), static_cast<float>(x2(i, 1)));
  }
  std::vector<int> visible;
  cv::filterHomographyDecompByVisibleRefpoints(rotations, normals, before, after, visible);
  std::vector<PlanarMotion> motions;
  // decomposeHomographyMat works on H scaled so that its middle singular value is 1,
  // which makes the returned translation that of a plane at distance 1.
  for (int k : visible) {
    PlanarMotion motion;
    cv::cv2eigen(rotations[k], motion.R);
    cv::cv2eigen(translations[k], motion.t);
    cv::cv2eigen(normals[k], motion.n);
    motions.push_back(motion);
  }
  return motions;
}

}  // namespace calibproj::geometry
