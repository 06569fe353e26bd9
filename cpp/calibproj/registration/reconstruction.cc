#include "calibproj/registration/reconstruction.h"
#include "calibproj/registration/noise_model.h"

#include "calibproj/registration/floor_frame.h"

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <map>
#include <optional>
#include <numeric>
#include <stdexcept>
#include <tuple>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "calibproj/ba/rotation.h"
#include "calibproj/common/limits.h"
#include "calibproj/common/quantile.h"
#include "calibproj/geometry/homography.h"
#include "calibproj/geometry/pnp.h"
#include "calibproj/geometry/triangulation.h"
#include "calibproj/registration/view_score.h"

namespace calibproj::registration {

namespace {

std::string Str(int v) { return std::to_string(v); }

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument(message);
}

Eigen::Matrix3d CameraMatrix(const ba::Intrinsics& K) {
  Eigen::Matrix3d M;
  M << K.fx, K.skew, K.cx, 0, K.fy, K.cy, 0, 0, 1;
  return M;
}

Eigen::Matrix3d PoseRotation(const ba::PoseMatrix& poses, int c) {
  return ba::RotationFromAngleAxis(poses.row(c).head<3>().transpose());
}

Eigen::Vector3d PoseTranslation(const ba::PoseMatrix& poses, int c) { return poses.row(c).tail<3>().transpose(); }

void SetPose(ba::PoseMatrix* poses, int c, const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  poses->row(c).head<3>() = ba::AngleAxisFromRotation(R).transpose();
  poses->row(c).tail<3>() = t.transpose();
}

// Floors of the estimated noise (camera pixels, projector pixels): a perfect fit on
// rendered data must not make one group's weight unbounded.
constexpr double kMinNoisePx = 0.005;
constexpr double kMinProjectorNoisePx = 0.002;
// Redundancy (observations beyond the parameters they determine) worth the pooled
// noise as a prior for one camera's noise.
constexpr double kPriorRedundancy = 10.0;
// Steps of the noise estimate between two adjustments, and the relative change of
// every sigma under which it has settled.
constexpr int kNoiseSteps = 200;
constexpr double kNoiseStepTolerance = 1e-3;
// Chi-square difference (in units of the camera's noise variance) below which the
// mirror pose of a planar view is not ruled out: 5 sigma.
constexpr double kAmbiguityEvidence = 25.0;
// Standard normal quantile of the relief test (ReliefTest): 99.9 %, so that a flat
// floor is taken for an uneven one in one calibration of a thousand.
constexpr double kReliefTestZ = 3.09;
// A relief is kept when it takes this many times that quantile off the chi-square.
// Detection errors that the cameras share (a smooth field over each image: blur, the
// lens model, a floor's texture) are not independent, and a relief takes some of them up:
// the rendered flat floors gave 100-370 against quantiles of 154 (demo room, 104 nodes)
// and 232 (or-full, 169), up to 2.4 times, where floors 3-6 mm uneven gave 213,000-482,000.
// A relief kept on a flat floor tilts the zoomed camera's patch by what it took up (a
// textured floor, 6 rooms: the zoomed camera 0.023-0.037 deg off with it, 0.012-0.016
// kept flat).
constexpr double kReliefSharedErrorFactor = 4.0;
// The relief test's grid is this many times coarser than the estimate's: whether the
// floor is uneven at all shows at that scale, and a finer grid's many nodes that few
// points pin would raise the test's bar (a chi-square over every node) without adding
// to its power.
constexpr int kReliefTestCoarsening = 2;
// The projector's apex (ba/relief_cost.h) joins a relief that takes this many times its
// bar off the chi-square. Its three parameters are measured by the parallax of raised
// centres; a relief at the noise's level (detection errors that share a smooth field:
// the rendered clean demo room, seed 2, 233 against a bar of 154) has none to measure
// them by, and its uncertain heights would only loosen what the projector says of the
// centres' places (there the zoomed camera's sigma 0.018 -> 0.027 deg). The same room
// on a floor 6 mm uneven: 123,000.
constexpr double kApexGainFactor = 10.0;
// Reconstructed points a raised surface needs before its outline decides where the
// projector draws (ProjectedPlane): fewer outline too small a part of it.
constexpr int kMinOutlinePoints = 6;
// Points of one plane a camera needs before its projector-to-camera homography on that
// plane is fitted (PlaceSingleViewPointsOnTheirSurfaces): a few beyond the four it takes.
constexpr int kMinPlaneMapPoints = 6;
// How many times better a plane's projector-to-camera homography must explain a point
// seen once than every other plane's before the point is put on it.
constexpr double kPlaneEvidence = 2.0;

// Robust standard deviation of 2D residuals from the median of their norms
// (for isotropic Gaussian noise, median |r| = sigma * sqrt(2 ln 2)).
double RobustSigma(std::vector<double> norms) {
  if (norms.empty()) return 0.0;
  const auto middle = norms.begin() + static_cast<long>(norms.size() / 2);
  std::nth_element(norms.begin(), middle, norms.end());
  return *middle / std::sqrt(2.0 * std::log(2.0));
}

// Median angle between the two viewing rays of each correspondence, for the relative
// motion of a planar-motion solution (camera 1 at the origin).
double MedianParallaxDeg(const geometry::PlanarMotion& motion, const geometry::Points2& x1,
                         const geometry::Points2& x2) {
  std::vector<double> angles;
  for (int i = 0; i < x1.rows(); ++i) {
    const std::vector<geometry::View> views = {
        {Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero(), x1.row(i).transpose()},
        {motion.R, motion.t, x2.row(i).transpose()}};
    const Eigen::Vector3d X = geometry::TriangulateLinear(views);
    if (X.allFinite()) angles.push_back(geometry::MaxTriangulationAngle(views, X));
  }
  if (angles.empty()) return 0.0;
  const auto middle = angles.begin() + static_cast<long>(angles.size() / 2);
  std::nth_element(angles.begin(), middle, angles.end());
  return *middle * 180.0 / M_PI;
}

}  // namespace

void Options::Check() const {
  for (const auto& [name, value] :
       {std::pair{"loss_scale_px", loss_scale_px}, {"homography_threshold_px", homography_threshold_px},
        {"pnp_threshold_px", pnp_threshold_px}, {"min_triangulation_angle_deg", min_triangulation_angle_deg},
        {"min_pair_parallax_deg", min_pair_parallax_deg}, {"outlier_threshold_px", outlier_threshold_px},
        {"outlier_sigma_factor", outlier_sigma_factor}, {"weak_rotation_sigma_deg", weak_rotation_sigma_deg}}) {
    limits::RequireFinite(value, std::string("registration: ") + name);
  }
  Require(homography_threshold_px > 0 && pnp_threshold_px > 0, "registration: RANSAC thresholds must be positive");
  limits::RequireInRange(ransac_max_iterations, 1, limits::kMaxIterations, "registration: ransac_max_iterations");
  Require(ransac_confidence > 0 && ransac_confidence < 1, "registration: ransac_confidence must be in (0, 1)");
  Require(min_pair_points >= 4, "registration: min_pair_points must be >= 4");
  Require(min_pnp_points >= 4, "registration: min_pnp_points must be >= 4");
  Require(min_triangulation_angle_deg >= 0, "registration: min_triangulation_angle_deg must be >= 0");
  Require(min_pair_parallax_deg >= 0, "registration: min_pair_parallax_deg must be >= 0");
  Require(outlier_threshold_px > 0 && outlier_sigma_factor >= 0, "registration: bad outlier threshold");
  limits::RequireInRange(max_refine_rounds, 1, 1000, "registration: max_refine_rounds");
  Require(view_score_levels >= 1 && view_score_levels <= 12, "registration: view_score_levels must be in [1, 12]");
  limits::RequireInRange(num_threads, 1, limits::kMaxThreads, "registration: num_threads");
  limits::RequireInRange(intermediate_ba_iterations, 0, limits::kMaxIterations,
                         "registration: intermediate_ba_iterations");
  limits::RequireInRange(final_ba_iterations, 0, limits::kMaxIterations, "registration: final_ba_iterations");
  Require(weak_rotation_sigma_deg > 0, "registration: weak_rotation_sigma_deg must be positive");
  limits::RequireInRange(max_planes, 0, 100, "registration: max_planes");
  limits::RequireInRange(min_plane_points, 3, limits::kMaxPoints, "registration: min_plane_points");
  limits::RequireInRange(plane_distance, 1e-9, 1.0, "registration: plane_distance");
  limits::RequireInRange(min_projector_pnp_points, 4, limits::kMaxPoints, "registration: min_projector_pnp_points");
  limits::RequireInRange(projector_sigma_px, 1e-6, 100.0, "registration: projector_sigma_px");
  limits::RequireInRange(error_correlation, 0.0, 1.0, "registration: error_correlation");
  limits::RequireInRange(shared_error_shift, 0.0, 100.0, "registration: shared_error_shift");
  limits::RequireInRange(shared_error_field, 0.0, 100.0, "registration: shared_error_field");
  limits::RequireInRange(floor_relief, 0.0, 0.1, "registration: floor_relief");
  limits::RequireInRange(relief_cells, 1, ba::kMaxReliefCells, "registration: relief_cells");
}

namespace {

struct PlanarPose {
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  double rms_px = 0.0;
};

double RmsReprojection(const std::vector<cv::Point3d>& object, const std::vector<cv::Point2d>& image,
                       const ba::Intrinsics& K, const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  double sum = 0.0;
  for (size_t i = 0; i < object.size(); ++i) {
    Eigen::Vector2d pixel;
    if (!ba::ProjectPoint(K, R * Eigen::Vector3d(object[i].x, object[i].y, object[i].z) + t, &pixel, nullptr)) {
      return std::numeric_limits<double>::infinity();
    }
    sum += (pixel - Eigen::Vector2d(image[i].x, image[i].y)).squaredNorm();
  }
  return std::sqrt(sum / static_cast<double>(object.size()));
}

// The two poses of a planar PnP (OpenCV's IPPE), best first; empty when it fails.
std::vector<PlanarPose> PlanarPoses(const std::vector<cv::Point3d>& object, const std::vector<cv::Point2d>& image,
                                    const ba::Intrinsics& K) {
  std::vector<PlanarPose> out;
  if (object.size() < 4) return out;
  std::vector<cv::Mat> rvecs, tvecs;
  try {
    const cv::Matx33d camera_matrix(K.fx, K.skew, K.cx, 0.0, K.fy, K.cy, 0.0, 0.0, 1.0);
    cv::solvePnPGeneric(object, image, camera_matrix, cv::noArray(), rvecs, tvecs, false, cv::SOLVEPNP_IPPE);
  } catch (const cv::Exception&) {
    return out;
  }
  for (size_t k = 0; k < rvecs.size() && k < tvecs.size(); ++k) {
    cv::Mat R;
    cv::Rodrigues(rvecs[k], R);
    PlanarPose pose;
    for (int r = 0; r < 3; ++r) {
      pose.t(r) = tvecs[k].at<double>(r);
      for (int c = 0; c < 3; ++c) pose.R(r, c) = R.at<double>(r, c);
    }
    pose.rms_px = RmsReprojection(object, image, K, pose.R, pose.t);
    if (std::isfinite(pose.rms_px)) out.push_back(pose);
  }
  std::sort(out.begin(), out.end(), [](const PlanarPose& a, const PlanarPose& b) { return a.rms_px < b.rms_px; });
  return out;
}

}  // namespace

Reconstruction::Reconstruction(std::vector<Camera> cameras, int num_points, Eigen::VectorXi camera_index,
                               Eigen::VectorXi point_index, PixelMatrix observed, Options options)
    : cameras_(std::move(cameras)),
      num_points_(num_points),
      camera_index_(std::move(camera_index)),
      point_index_(std::move(point_index)),
      observed_(std::move(observed)),
      options_(options) {
  options_.Check();
  const int num_obs = static_cast<int>(camera_index_.size());
  Require(!cameras_.empty(), "registration: no cameras");
  limits::RequireInRange(num_points_, 0, limits::kMaxPoints, "registration: num_points");
  Require(point_index_.size() == num_obs && observed_.rows() == num_obs,
          "registration: camera_index, point_index and observed have different lengths");
  Require(observed_.allFinite(), "registration: non-finite observation");
  for (size_t c = 0; c < cameras_.size(); ++c) {
    const Camera& cam = cameras_[c];
    Require(cam.K.fx > 0 && cam.K.fy > 0 && std::isfinite(cam.K.fx * cam.K.fy) && std::isfinite(cam.K.cx) &&
                std::isfinite(cam.K.cy) && std::isfinite(cam.K.skew),
            "registration: camera " + Str(int(c)) + " has invalid intrinsics");
    Require(cam.width > 0 && cam.height > 0 && cam.width <= limits::kMaxImageSide &&
                cam.height <= limits::kMaxImageSide,
            "registration: camera " + Str(int(c)) + " has no valid image size");
  }
  camera_observations_.assign(cameras_.size(), {});
  point_observations_.assign(num_points_, {});
  for (int i = 0; i < num_obs; ++i) {
    const int c = camera_index_(i), p = point_index_(i);
    if (c < 0 || c >= num_cameras()) throw std::invalid_argument("registration: observation " + Str(i) + " has camera index " + Str(c) + " out of range");
    if (p < 0 || p >= num_points_) throw std::invalid_argument("registration: observation " + Str(i) + " has point index " + Str(p) + " out of range");
    camera_observations_[c].push_back(i);
    point_observations_[p].push_back(i);
  }
  registered_.assign(cameras_.size(), false);
  failure_.assign(cameras_.size(), "");
  poses_ = ba::PoseMatrix::Zero(num_cameras(), 6);
  points_ = ba::PointMatrix::Zero(num_points_, 3);
  reconstructed_.assign(num_points_, false);
  point_plane_.assign(num_points_, -1);
  single_view_.assign(num_points_, false);
  active_.assign(num_obs, true);
  camera_sigma_px_.assign(cameras_.size(), std::numeric_limits<double>::quiet_NaN());
  lenses_.assign(cameras_.size(), std::nullopt);
}

namespace {

bool SymmetricPositiveSemiDefinite(const Eigen::MatrixXd& m) {
  if (!m.allFinite() || (m - m.transpose()).norm() > 1e-9 * std::max(1.0, m.norm())) return false;
  if (m.size() == 0) return true;
  const double largest = std::max(1e-300, m.diagonal().cwiseAbs().maxCoeff());
  return Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(m).eigenvalues().minCoeff() >= -1e-9 * largest;
}

}  // namespace

void Reconstruction::SetLensUncertainty(int camera, const LensUncertainty& lens) {
  Require(camera >= 0 && camera < num_cameras(), "lens: camera " + Str(camera) + " out of range");
  const ba::Intrinsics& K = cameras_[camera].K;
  for (double value : lens.lens) Require(std::isfinite(value), "lens: non-finite entry");
  Require(std::abs(lens.lens[selfcal::kFocal] - K.fx) <= 1e-9 * K.fx && std::abs(lens.lens[selfcal::kCx] - K.cx) <= 1e-6 &&
              std::abs(lens.lens[selfcal::kCy] - K.cy) <= 1e-6,
          "lens: camera " + Str(camera) + "'s lens is not the one of its intrinsics");
  Require(SymmetricPositiveSemiDefinite(lens.covariance),
          "lens: camera " + Str(camera) + "'s covariance is not a finite symmetric positive semi-definite matrix");
  lenses_[camera] = lens;
  if (lens_cross_covariance_.size() > 0) {  // a new lens: how it errs with the others is not known
    lens_cross_covariance_.middleRows(selfcal::kLensSize * camera, selfcal::kLensSize).setZero();
    lens_cross_covariance_.middleCols(selfcal::kLensSize * camera, selfcal::kLensSize).setZero();
  }
}

void Reconstruction::SetLensCrossCovariances(const std::vector<int>& cameras, const Eigen::MatrixXd& joint) {
  constexpr int L = selfcal::kLensSize;
  const int n = static_cast<int>(cameras.size());
  Require(joint.rows() == L * n && joint.cols() == L * n,
          "lens cross covariances: expected a " + Str(L * n) + " x " + Str(L * n) + " matrix for " + Str(n) + " cameras");
  Require(SymmetricPositiveSemiDefinite(joint), "lens cross covariances: not a finite symmetric positive semi-definite matrix");
  std::vector<bool> seen(cameras_.size(), false);
  for (int k = 0; k < n; ++k) {
    const int c = cameras[k];
    Require(c >= 0 && c < num_cameras() && !seen[c], "lens cross covariances: camera " + Str(c) + " out of range or repeated");
    seen[c] = true;
    Require(lenses_[c].has_value(), "lens cross covariances: camera " + Str(c) + " has no lens (set_lens_uncertainty)");
    const LensCovariance own = joint.block<L, L>(L * k, L * k);
    Require((own - lenses_[c]->covariance).norm() <= 1e-9 * std::max(1e-300, own.norm()),
            "lens cross covariances: camera " + Str(c) + "'s block differs from its lens's covariance");
  }
  if (lens_cross_covariance_.size() == 0) lens_cross_covariance_ = Eigen::MatrixXd::Zero(L * num_cameras(), L * num_cameras());
  for (int a = 0; a < n; ++a) {
    for (int b = 0; b < n; ++b) {
      if (a != b) lens_cross_covariance_.block<L, L>(L * cameras[a], L * cameras[b]) = joint.block<L, L>(L * a, L * b);
    }
  }
}

void Reconstruction::AddLenses(const std::vector<int>& cameras, ba::Data* data) const {
  if (std::none_of(cameras.begin(), cameras.end(), [&](int c) { return lenses_[c].has_value(); })) return;
  data->lens_block = Eigen::VectorXi::Constant(static_cast<int>(cameras.size()), -1);
  int blocks = 0;
  for (size_t k = 0; k < cameras.size(); ++k) {
    if (lenses_[cameras[k]]) data->lens_block(static_cast<int>(k)) = blocks++;
  }
  data->lens_jacobians = ba::LensJacobianMatrix::Zero(data->camera_index.size(), 2 * ba::kLensBlockSize);
  for (int i = 0; i < data->camera_index.size(); ++i) {
    const int k = data->camera_index(i);
    const auto& lens = lenses_[cameras[k]];
    if (!lens) continue;
    const ba::Intrinsics& K = data->intrinsics[k];
    const double y = (data->observed(i, 1) - K.cy) / K.fy;
    const Eigen::Vector2d normalised((data->observed(i, 0) - K.cx - K.skew * y) / K.fx, y);
    const selfcal::LensJacobian J = selfcal::ResidualByLens(lens->lens, lens->shape, normalised);
    data->lens_jacobians.row(i) = Eigen::Map<const Eigen::Matrix<double, 1, 2 * ba::kLensBlockSize>>(J.data());
  }
}

void Reconstruction::SetProjector(const PixelMatrix& pixels, double width, double height,
                                  const std::vector<double>& marker_side_px) {
  Require(pixels.rows() == num_points_, "registration: " + Str(int(pixels.rows())) + " projector pixels for " +
                                            Str(num_points_) + " points");
  Require(marker_side_px.empty() || static_cast<int>(marker_side_px.size()) == num_points_,
          "registration: " + Str(static_cast<int>(marker_side_px.size())) + " marker sides for " + Str(num_points_) +
              " points");
  for (const double side : marker_side_px) {
    Require(std::isnan(side) || (side > 0.0 && side <= limits::kMaxImageSide),
            "registration: a marker side must be positive and at most the largest image side, or NaN");
  }
  Require(width >= 1.0 && height >= 1.0 && width <= limits::kMaxImageSide && height <= limits::kMaxImageSide,
          "registration: the projector needs a valid image size");
  projector_.resize(num_points_, 2);
  const Eigen::RowVector2d centre(0.5 * (width - 1.0), 0.5 * (height - 1.0));
  for (int p = 0; p < num_points_; ++p) {
    const bool known = pixels.row(p).allFinite();
    Require(known || pixels.row(p).array().isNaN().all(),
            "registration: projector pixel of point " + Str(p) + " must be finite or NaN");
    projector_.row(p) = known ? Eigen::RowVector2d((pixels.row(p) - centre) / width)
                              : Eigen::RowVector2d::Constant(std::numeric_limits<double>::quiet_NaN());
  }
  projector_width_ = width;
  GroupProjectorPoints(marker_side_px);
}

void Reconstruction::GroupProjectorPoints(const std::vector<double>& marker_side_px) {
  // One group per distinct side (NaN, a side not known, being one too), in the order of
  // their first point.
  projector_group_.assign(num_points_, -1);
  projector_group_side_px_.clear();
  for (int p = 0; p < num_points_; ++p) {
    if (!projector_.row(p).allFinite()) continue;
    const double side = marker_side_px.empty() ? std::numeric_limits<double>::quiet_NaN() : marker_side_px[p];
    const auto same = [side](double other) { return std::isnan(side) ? std::isnan(other) : other == side; };
    const auto found = std::find_if(projector_group_side_px_.begin(), projector_group_side_px_.end(), same);
    projector_group_[p] = static_cast<int>(found - projector_group_side_px_.begin());
    if (found == projector_group_side_px_.end()) projector_group_side_px_.push_back(side);
  }
  projector_sigma_px_.assign(projector_group_side_px_.size(), options_.projector_sigma_px);
  projector_sigma_estimated_ = false;
}

std::vector<double> Reconstruction::projector_sigma_px() const {
  if (projector_sigma_estimated_) return projector_sigma_px_;
  return std::vector<double>(projector_sigma_px_.size(), std::numeric_limits<double>::quiet_NaN());
}

void Reconstruction::OutlineSurfaces() {
  // A raised surface (a table top) hides the floor under it from the projector: the
  // projector pixels it receives are those inside the outline of its reconstructed points.
  surface_outlines_.assign(more_planes_.size() + 1, {});
  if (!HasProjector()) return;
  for (size_t k = 1; k < surface_outlines_.size(); ++k) {
    std::vector<cv::Point2f> pixels;
    for (int p = 0; p < num_points_; ++p) {
      if (reconstructed_[p] && point_plane_[p] == static_cast<int>(k) && projector_.row(p).allFinite()) {
        pixels.emplace_back(static_cast<float>(projector_(p, 0)), static_cast<float>(projector_(p, 1)));
      }
    }
    if (static_cast<int>(pixels.size()) < kMinOutlinePoints) continue;
    cv::convexHull(pixels, surface_outlines_[k]);
  }
}

int Reconstruction::ProjectedPlane(int point) const {
  if (!HasProjector() || point < 0 || point >= num_points_ || !projector_.row(point).allFinite()) return -1;
  // The innermost outline holding the pixel: a box on the table is drawn on, not the table.
  const cv::Point2f pixel(static_cast<float>(projector_(point, 0)), static_cast<float>(projector_(point, 1)));
  int plane = 0;
  double smallest = std::numeric_limits<double>::infinity();
  for (size_t k = 1; k < surface_outlines_.size(); ++k) {
    const std::vector<cv::Point2f>& outline = surface_outlines_[k];
    if (outline.size() < 3 || cv::pointPolygonTest(outline, pixel, false) < 0) continue;
    const double area = cv::contourArea(outline);
    if (area < smallest) {
      smallest = area;
      plane = static_cast<int>(k);
    }
  }
  return plane;
}

bool Reconstruction::ProjectorPrediction(int point, Eigen::Vector3d* X) const {
  const int plane = ProjectedPlane(point);
  if (plane < 0 || plane >= static_cast<int>(projector_surfaces_.size())) return false;
  return ba::ProjectorPoint(projector_surfaces_[plane], projector_lens_, projector_.row(point).transpose(), X);
}

bool Reconstruction::AllOnOnePlane(const std::vector<int>& observations, const std::vector<int>& subset) const {
  if (options_.model != ba::Model::kCoplanar || subset.empty()) return false;
  int plane = -1;
  for (const int k : subset) {
    const int p = point_index_(observations[k]);
    const int on = reconstructed_[p] ? point_plane_[p] : ProjectedPlane(p);
    if (on < 0 || (plane >= 0 && on != plane)) return false;
    plane = on;
  }
  return true;
}

bool Reconstruction::KnownPoint(int point, Eigen::Vector3d* X) const {
  if (reconstructed_[point]) {
    *X = points_.row(point).transpose();
    return true;
  }
  return ProjectorPrediction(point, X);
}

double Reconstruction::MainPlaneExtent(const std::vector<int>& points) const {
  // Between the 1st and 99th percentiles along each axis: a stray point does not count.
  double extent = 0.0;
  for (int axis = 0; axis < 3; ++axis) {
    std::vector<double> values;
    for (int p : points) {
      if (point_plane_[p] == 0) values.push_back(points_(p, axis));
    }
    if (values.size() < 2) return 0.0;
    extent = std::max(extent, Quantile(values, 0.99) - Quantile(values, 0.01));
  }
  return std::isfinite(extent) ? extent : 0.0;
}

double Reconstruction::Focal(int camera) const { return 0.5 * (cameras_[camera].K.fx + cameras_[camera].K.fy); }

Eigen::Vector2d Reconstruction::Ray(int observation) const {
  const ba::Intrinsics& K = cameras_[camera_index_(observation)].K;
  const double y = (observed_(observation, 1) - K.cy) / K.fy;
  const double x = (observed_(observation, 0) - K.cx - K.skew * y) / K.fx;
  return {x, y};
}

int Reconstruction::ViewScore(int camera) const {
  Require(camera >= 0 && camera < num_cameras(), "view score: camera index out of range");
  VisibilityPyramid pyramid(options_.view_score_levels, cameras_[camera].width, cameras_[camera].height);
  for (int i : camera_observations_[camera]) {
    if (active_[i]) pyramid.Add(observed_(i, 0), observed_(i, 1));
  }
  return pyramid.Score();
}

std::vector<int> Reconstruction::CommonObservations(int camera1, int camera2, std::vector<int>* second) const {
  std::map<int, int> in_second;  // point -> observation of camera2
  for (int i : camera_observations_[camera2]) {
    if (active_[i]) in_second[point_index_(i)] = i;
  }
  std::vector<int> first;
  second->clear();
  for (int i : camera_observations_[camera1]) {
    if (!active_[i]) continue;
    const auto it = in_second.find(point_index_(i));
    if (it == in_second.end()) continue;
    first.push_back(i);
    second->push_back(it->second);
  }
  return first;
}

std::vector<int> Reconstruction::ComponentSizes() const {
  // Cameras are connected when they share enough points for PnP.
  std::vector<int> component(num_cameras());
  std::iota(component.begin(), component.end(), 0);
  const auto find = [&component](int c) {
    while (component[c] != c) c = component[c] = component[component[c]];
    return c;
  };
  for (int c1 = 0; c1 < num_cameras(); ++c1) {
    for (int c2 = c1 + 1; c2 < num_cameras(); ++c2) {
      std::vector<int> second;
      if (static_cast<int>(CommonObservations(c1, c2, &second).size()) >= options_.min_pnp_points) {
        component[find(c1)] = find(c2);
      }
    }
  }
  std::vector<int> size(num_cameras(), 0);
  for (int c = 0; c < num_cameras(); ++c) ++size[find(c)];
  std::vector<int> out(num_cameras());
  for (int c = 0; c < num_cameras(); ++c) out[c] = size[find(c)];
  return out;
}

std::vector<PairCandidate> Reconstruction::RankInitialPairs() const {
  const std::vector<int> component_size = ComponentSizes();
  std::vector<PairCandidate> pairs;
  for (int c1 = 0; c1 < num_cameras(); ++c1) {
    for (int c2 = c1 + 1; c2 < num_cameras(); ++c2) {
      std::vector<int> second;
      const std::vector<int> first = CommonObservations(c1, c2, &second);
      if (static_cast<int>(first.size()) < options_.min_pair_points) continue;
      VisibilityPyramid p1(options_.view_score_levels, cameras_[c1].width, cameras_[c1].height);
      VisibilityPyramid p2(options_.view_score_levels, cameras_[c2].width, cameras_[c2].height);
      for (size_t k = 0; k < first.size(); ++k) {
        p1.Add(observed_(first[k], 0), observed_(first[k], 1));
        p2.Add(observed_(second[k], 0), observed_(second[k], 1));
      }
      pairs.push_back({c1, c2, p1.Score(), p2.Score(), static_cast<int>(first.size()), component_size[c1]});
    }
  }
  // Start in the largest group of connected cameras; there maximise both scores: the
  // smaller one first, then the larger, then the point count.
  std::sort(pairs.begin(), pairs.end(), [](const PairCandidate& a, const PairCandidate& b) {
    const auto key = [](const PairCandidate& p) {
      return std::make_tuple(p.connected_cameras, std::min(p.score1, p.score2), std::max(p.score1, p.score2),
                             p.common_points, -p.camera1, -p.camera2);
    };
    return key(a) > key(b);
  });
  return pairs;
}

void Reconstruction::ResetStructure() {
  std::fill(registered_.begin(), registered_.end(), false);
  std::fill(reconstructed_.begin(), reconstructed_.end(), false);
  std::fill(point_plane_.begin(), point_plane_.end(), -1);
  std::fill(single_view_.begin(), single_view_.end(), false);
  more_planes_.clear();
  surface_outlines_.clear();
  order_.clear();
  gauge_camera_ = -1;
}

void Reconstruction::SetInitialStructure(int camera1, int camera2, const Eigen::Matrix3d& R,
                                         const Eigen::Vector3d& t, const Eigen::Vector3d& n) {
  ResetStructure();
  SetPose(&poses_, camera1, Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero());
  SetPose(&poses_, camera2, R, t);
  registered_[camera1] = registered_[camera2] = true;
  order_ = {camera1, camera2};
  gauge_camera_ = camera1;
  plane_ << n.normalized(), 1.0;  // the first camera is at distance 1 from the plane
  AddPoints(camera1);
  AddPoints(camera2);
}

int Reconstruction::ThirdCamera(int camera1, int camera2) const {
  int best = -1;
  size_t best_count = 0;
  for (int c = 0; c < num_cameras(); ++c) {
    if (c == camera1 || c == camera2 || !failure_[c].empty()) continue;
    std::vector<int> second;
    const size_t count = CommonObservations(camera1, c, &second).size();
    if (count >= static_cast<size_t>(options_.min_pair_points) && count > best_count) {
      best = c;
      best_count = count;
    }
  }
  return best;
}

InitialPairResult Reconstruction::Initialize(int camera1, int camera2) {
  Require(camera1 >= 0 && camera1 < num_cameras() && camera2 >= 0 && camera2 < num_cameras() && camera1 != camera2,
          "initialize: two different cameras in range are needed");
  InitialPairResult result;
  std::vector<int> second;
  const std::vector<int> first = CommonObservations(camera1, camera2, &second);
  geometry::Points2 x1(first.size(), 2), x2(first.size(), 2);
  for (size_t k = 0; k < first.size(); ++k) {
    x1.row(k) = Ray(first[k]).transpose();
    x2.row(k) = Ray(second[k]).transpose();
  }
  geometry::HomographyRansacOptions ransac;
  ransac.threshold_px = options_.homography_threshold_px;
  ransac.focal1 = Focal(camera1);
  ransac.focal2 = Focal(camera2);
  ransac.max_iterations = options_.ransac_max_iterations;
  ransac.confidence = options_.ransac_confidence;
  ransac.seed = options_.seed;
  const geometry::HomographyEstimate homography = geometry::EstimateHomographyRansac(x1, x2, ransac);
  result.homography_inliers = static_cast<int>(homography.inliers.size());
  if (!homography.success || result.homography_inliers < options_.min_pair_points) {
    result.reason = "homography: " + Str(result.homography_inliers) + " inliers of " + Str(int(first.size())) +
                    " common points (need " + Str(options_.min_pair_points) + ")";
    return result;
  }
  geometry::Points2 in1(homography.inliers.size(), 2), in2(homography.inliers.size(), 2);
  for (size_t k = 0; k < homography.inliers.size(); ++k) {
    in1.row(k) = x1.row(homography.inliers[k]);
    in2.row(k) = x2.row(homography.inliers[k]);
  }
  std::vector<geometry::PlanarMotion> motions = geometry::DecomposeHomography(homography.H, in1, in2);
  result.solutions = static_cast<int>(motions.size());
  if (motions.empty()) {
    result.reason = "homography decomposition: no solution puts the points in front of both cameras";
    return result;
  }

  // Both solutions share the baseline; without parallax neither the plane nor the
  // points are determined (two cameras at nearly the same place see the same image).
  const double parallax_deg = MedianParallaxDeg(motions.front(), in1, in2);
  result.median_parallax_deg = parallax_deg;
  if (parallax_deg < options_.min_pair_parallax_deg) {
    result.reason = "baseline too short: median triangulation angle " + std::to_string(parallax_deg) +
                    " deg (need " + std::to_string(options_.min_pair_parallax_deg) + ")";
    return result;
  }

  // Two-fold ambiguity: the third camera's homography with camera1 gives the plane
  // normal again; the true solution agrees with it.
  const int third = motions.size() > 1 ? ThirdCamera(camera1, camera2) : -1;
  if (third >= 0) {
    std::vector<int> third_obs;
    const std::vector<int> shared = CommonObservations(camera1, third, &third_obs);
    geometry::Points2 y1(shared.size(), 2), y3(shared.size(), 2);
    for (size_t k = 0; k < shared.size(); ++k) {
      y1.row(k) = Ray(shared[k]).transpose();
      y3.row(k) = Ray(third_obs[k]).transpose();
    }
    ransac.focal2 = Focal(third);
    const geometry::HomographyEstimate h13 = geometry::EstimateHomographyRansac(y1, y3, ransac);
    std::vector<geometry::PlanarMotion> third_motions;
    if (h13.success) {
      geometry::Points2 z1(h13.inliers.size(), 2), z3(h13.inliers.size(), 2);
      for (size_t k = 0; k < h13.inliers.size(); ++k) {
        z1.row(k) = y1.row(h13.inliers[k]);
        z3.row(k) = y3.row(h13.inliers[k]);
      }
      third_motions = geometry::DecomposeHomography(h13.H, z1, z3);
    }
    if (!third_motions.empty()) {
      double best_agreement = -2.0;
      size_t best = 0;
      for (size_t k = 0; k < motions.size(); ++k) {
        for (const auto& other : third_motions) {
          const double agreement = motions[k].n.dot(other.n);
          if (agreement > best_agreement) {
            best_agreement = agreement;
            best = k;
          }
        }
      }
      motions = {motions[best]};
      result.third_camera = third;
      result.normal_agreement = best_agreement;
    }
  }

  // Without a third camera: refine each solution and keep the lower cost.
  double best_cost = std::numeric_limits<double>::infinity();
  ba::PoseMatrix best_poses;
  ba::PointMatrix best_points;
  Eigen::Vector4d best_plane = Eigen::Vector4d::Zero();
  std::vector<bool> best_reconstructed;
  std::vector<int> best_point_plane;
  std::vector<bool> best_single_view;
  for (const auto& motion : motions) {
    SetInitialStructure(camera1, camera2, motion.R, motion.t, motion.n);
    if (motions.size() == 1) break;
    const AdjustResult adjusted = Adjust(false);
    if (adjusted.final_cost < best_cost) {
      best_cost = adjusted.final_cost;
      best_poses = poses_;
      best_points = points_;
      best_plane = plane_;
      best_reconstructed = reconstructed_;
      best_point_plane = point_plane_;
      best_single_view = single_view_;
    }
  }
  if (motions.size() > 1) {
    poses_ = best_poses;
    points_ = best_points;
    plane_ = best_plane;
    reconstructed_ = best_reconstructed;
    point_plane_ = best_point_plane;
    single_view_ = best_single_view;
  }
  result.points = static_cast<int>(std::count(reconstructed_.begin(), reconstructed_.end(), true));
  result.success = result.points >= options_.min_pair_points / 2;
  if (!result.success) result.reason = "only " + Str(result.points) + " points could be reconstructed";
  return result;
}

NextCameraCandidate Reconstruction::ChooseNextCamera() const {
  NextCameraCandidate best;
  for (int c = 0; c < num_cameras(); ++c) {
    if (registered_[c] || !failure_[c].empty()) continue;
    VisibilityPyramid pyramid(options_.view_score_levels, cameras_[c].width, cameras_[c].height);
    int count = 0;
    Eigen::Vector3d X;
    for (int i : camera_observations_[c]) {
      if (active_[i] && KnownPoint(point_index_(i), &X)) {
        pyramid.Add(observed_(i, 0), observed_(i, 1));
        ++count;
      }
    }
    if (count < MinPnpPoints()) continue;
    if (pyramid.Score() > best.score || (pyramid.Score() == best.score && count > best.points)) {
      best = {c, pyramid.Score(), count};
    }
  }
  return best;
}

RegisterResult Reconstruction::RegisterCamera(int camera) {
  Require(camera >= 0 && camera < num_cameras(), "register: camera index out of range");
  RegisterResult result;
  // Points placed by the registered cameras, and, with the projector, those it places.
  std::vector<int> observations;
  std::vector<Eigen::Vector3d> known;
  for (int i : camera_observations_[camera]) {
    Eigen::Vector3d X;
    if (active_[i] && KnownPoint(point_index_(i), &X)) {
      observations.push_back(i);
      known.push_back(X);
    }
  }
  result.correspondences = static_cast<int>(observations.size());
  geometry::Points3 X(observations.size(), 3);
  geometry::Points2 pixels(observations.size(), 2);
  for (size_t k = 0; k < observations.size(); ++k) {
    X.row(k) = known[k].transpose();
    pixels.row(k) = observed_.row(observations[k]);
  }
  geometry::PnpOptions pnp;
  pnp.threshold_px = options_.pnp_threshold_px;
  pnp.max_iterations = options_.ransac_max_iterations;
  pnp.confidence = options_.ransac_confidence;
  pnp.min_inliers = MinPnpPoints();
  geometry::PnpEstimate estimate = geometry::EstimatePoseRansac(X, pixels, CameraMatrix(cameras_[camera].K), pnp);
  result.inliers = static_cast<int>(estimate.inliers.size());
  if (!estimate.success) {
    result.reason = !estimate.problem.empty()
                        ? "PnP failed: " + estimate.problem
                        : "PnP failed: " + Str(result.inliers) + " inliers of " + Str(result.correspondences) +
                              " correspondences (need " + Str(MinPnpPoints()) + ")";
    failure_[camera] = result.reason;
    return result;
  }
  // Points on one plane seen nearly affinely fit two mirror poses; RANSAC's solver may
  // return the worse one. IPPE gives both: the one that fits the inliers best is kept.
  if (AllOnOnePlane(observations, estimate.inliers)) {
    std::vector<cv::Point3d> object;
    std::vector<cv::Point2d> image;
    for (const int k : estimate.inliers) {
      object.emplace_back(X(k, 0), X(k, 1), X(k, 2));
      image.emplace_back(pixels(k, 0), pixels(k, 1));
    }
    const std::vector<PlanarPose> planar = PlanarPoses(object, image, cameras_[camera].K);
    if (!planar.empty() &&
        planar[0].rms_px < RmsReprojection(object, image, cameras_[camera].K, estimate.R, estimate.t)) {
      estimate.R = planar[0].R;
      estimate.t = planar[0].t;
    }
  }
  // Refine the pose on the inliers with the points held fixed.
  ba::Data data;
  data.intrinsics = {cameras_[camera].K};
  data.poses.resize(1, 6);
  data.poses.row(0) << ba::AngleAxisFromRotation(estimate.R).transpose(), estimate.t.transpose();
  data.points.resize(result.inliers, 3);
  data.camera_index = Eigen::VectorXi::Zero(result.inliers);
  data.point_index.resize(result.inliers);
  data.observed.resize(result.inliers, 2);
  for (int k = 0; k < result.inliers; ++k) {
    data.points.row(k) = X.row(estimate.inliers[k]);
    data.point_index(k) = k;
    data.observed.row(k) = pixels.row(estimate.inliers[k]);
  }
  ba::Options refine;
  refine.refine_points = false;
  refine.max_iterations = options_.final_ba_iterations;
  try {
    const ba::Result refined = ba::BundleAdjust(data, refine);
    poses_.row(camera) = refined.poses.row(0);
    result.mean_error_px = refined.residuals.rowwise().norm().mean();
  } catch (const std::invalid_argument& error) {
    result.reason = std::string("pose refinement failed: ") + error.what();
    failure_[camera] = result.reason;
    return result;
  }
  if (result.mean_error_px > options_.pnp_threshold_px) {
    result.reason = "PnP pose inconsistent: mean error " + std::to_string(result.mean_error_px) +
                    " px over its inliers after refinement";
    failure_[camera] = result.reason;
    return result;
  }
  registered_[camera] = true;
  order_.push_back(camera);
  // Observations the PnP pose does not explain stay in: a zoomed camera resolves the
  // points far better than the cameras that placed them, so its residuals are large
  // until the points move. The intermediate adjustment's robust loss caps gross
  // outliers, and FilterOutliers decides afterwards.
  // Cameras that failed earlier may succeed now that more points are reconstructed.
  for (int c = 0; c < num_cameras(); ++c) {
    if (!registered_[c]) failure_[c].clear();
  }
  result.success = true;
  return result;
}

std::vector<Eigen::Matrix3d> Reconstruction::Rotations() const {
  std::vector<Eigen::Matrix3d> rotations(num_cameras());
  for (int c = 0; c < num_cameras(); ++c) rotations[c] = PoseRotation(poses_, c);
  return rotations;
}

bool Reconstruction::InFront(int observation, const std::vector<Eigen::Matrix3d>& rotations) const {
  const int c = camera_index_(observation);
  const Eigen::Vector3d X = points_.row(point_index_(observation)).transpose();
  return (rotations[c] * X + PoseTranslation(poses_, c)).z() > 0.0;
}

namespace {

// The point of `plane` that best fits the views (least squares on their linearised
// reprojection equations, in normalised coordinates), and each view's error in pixels.
bool BestPointOnPlane(const std::vector<geometry::View>& views, const std::vector<double>& focal,
                      const std::vector<size_t>& used, const Eigen::Vector4d& plane, Eigen::Vector3d* X,
                      std::vector<double>* error_px) {
  const Eigen::Vector3d n = plane.head<3>() / plane.head<3>().norm();
  const double d = plane(3) / plane.head<3>().norm();
  Eigen::Vector3d u = n.unitOrthogonal();
  const Eigen::Vector3d v = n.cross(u);
  const Eigen::Vector3d X0 = d * n;
  Eigen::MatrixXd A(2 * used.size(), 2);
  Eigen::VectorXd b(2 * used.size());
  for (size_t r = 0; r < used.size(); ++r) {
    const geometry::View& view = views[used[r]];
    // x_cam = R (X0 + a u + b v) + t; (x - ray_x z) = 0 and (y - ray_y z) = 0, divided by
    // the depth where the view's ray meets the plane and times its focal: about pixels.
    Eigen::Vector3d hit;
    if (!geometry::IntersectRayWithPlane(view, plane, &hit)) return false;
    const double depth = (view.R * hit + view.t).z();
    const Eigen::Vector3d c0 = view.R * X0 + view.t, cu = view.R * u, cv = view.R * v;
    for (int k = 0; k < 2; ++k) {
      const double w = focal[used[r]] / std::max(depth, 1e-12);
      A(2 * r + k, 0) = w * (cu(k) - view.ray(k) * cu.z());
      A(2 * r + k, 1) = w * (cv(k) - view.ray(k) * cv.z());
      b(2 * r + k) = -w * (c0(k) - view.ray(k) * c0.z());
    }
  }
  const Eigen::Vector2d ab = A.colPivHouseholderQr().solve(b);
  if (!ab.allFinite()) return false;
  *X = X0 + ab(0) * u + ab(1) * v;
  error_px->assign(views.size(), std::numeric_limits<double>::infinity());
  for (const size_t k : used) {
    const Eigen::Vector3d x_cam = views[k].R * *X + views[k].t;
    if (x_cam.z() > 0.0) (*error_px)[k] = focal[k] * (x_cam.head<2>() / x_cam.z() - views[k].ray).norm();
  }
  return true;
}

// The plane whose homography (projector pixel to camera pixel; empty: not known) maps
// `projector` nearest `observed`, when it does so at least twice as well as any other;
// -1 otherwise.
int PlaneExplaining(const std::vector<cv::Mat>& maps, const cv::Point2d& projector, const cv::Point2d& observed) {
  int best = -1;
  double best_error = std::numeric_limits<double>::infinity(), second = best_error;
  for (size_t k = 0; k < maps.size(); ++k) {
    if (maps[k].empty()) continue;
    std::vector<cv::Point2d> mapped;
    cv::perspectiveTransform(std::vector<cv::Point2d>{projector}, mapped, maps[k]);
    const double error = cv::norm(mapped[0] - observed);
    if (!std::isfinite(error)) continue;
    if (error < best_error) {
      second = best_error;
      best_error = error;
      best = static_cast<int>(k);
    } else {
      second = std::min(second, error);
    }
  }
  return best >= 0 && kPlaneEvidence * best_error < second ? best : -1;
}

}  // namespace

bool Reconstruction::PlanePointByConsensus(const std::vector<geometry::View>& views,
                                           const std::vector<double>& focal, const Eigen::Vector4d& plane,
                                           Eigen::Vector3d* X) const {
  // The point of the plane that best fits the views, the worst view left out while
  // one misses it by more than the homography threshold. A point seen once counts too.
  // Seen twice or more and fitting no two views, it lies off the plane (on a table
  // left in the projection) or its views are outliers: not placed.
  std::vector<size_t> used(views.size());
  std::iota(used.begin(), used.end(), size_t{0});
  std::vector<double> error_px;
  while (!used.empty()) {
    if (!BestPointOnPlane(views, focal, used, plane, X, &error_px)) return false;
    const auto worst = std::max_element(used.begin(), used.end(),
                                        [&](size_t a, size_t b) { return error_px[a] < error_px[b]; });
    if (error_px[*worst] <= options_.homography_threshold_px) return views.size() == 1 || used.size() >= 2;
    used.erase(worst);
    if (used.size() < 2) return false;
  }
  return false;
}

bool Reconstruction::TriangulatePoint(const std::vector<geometry::View>& views, Eigen::Vector3d* X) const {
  if (views.size() < 2) return false;
  *X = geometry::TriangulateLinear(views);
  if (!X->allFinite()) return false;
  if (geometry::MaxTriangulationAngle(views, *X) < options_.min_triangulation_angle_deg * M_PI / 180.0) return false;
  for (const auto& view : views) {
    if ((view.R * *X + view.t).z() <= 0.0) return false;
  }
  return true;
}

bool Reconstruction::ReconstructPoint(int point, int alone_on) {
  std::vector<geometry::View> views;
  std::vector<double> focal;  // pixels per unit of normalised image coordinates, per view
  for (int i : point_observations_[point]) {
    const int c = camera_index_(i);
    if (!active_[i] || !registered_[c]) continue;
    views.push_back({PoseRotation(poses_, c), PoseTranslation(poses_, c), Ray(i)});
    focal.push_back(std::sqrt(cameras_[c].K.fx * cameras_[c].K.fy));
  }
  if (views.empty()) return false;
  Eigen::Vector3d X;
  if (options_.model == ba::Model::kCoplanar) {
    // On the main plane, else on another plane found, else off every plane: a point
    // of a table left in the projection, triangulated when seen twice. Seen once, on
    // the plane given, else the main plane.
    int on = -1;
    for (int k = 0; k <= static_cast<int>(more_planes_.size()) && on < 0; ++k) {
      const Eigen::Vector4d& plane = k == 0 ? plane_ : more_planes_[k - 1];
      if ((views.size() > 1 || k == std::max(alone_on, 0)) && PlanePointByConsensus(views, focal, plane, &X)) on = k;
    }
    if (on < 0 && !TriangulatePoint(views, &X)) return false;
    point_plane_[point] = on;
    single_view_[point] = views.size() == 1;
  } else if (!TriangulatePoint(views, &X)) {
    return false;
  }
  points_.row(point) = X.transpose();
  reconstructed_[point] = true;
  return true;
}

bool Reconstruction::OnlyView(int observation) const {
  for (const int i : point_observations_[point_index_(observation)]) {
    if (i != observation && active_[i] && registered_[camera_index_(i)]) return false;
  }
  return true;
}

bool Reconstruction::ProjectorContradictsSingleView(int observation) const {
  const int p = point_index_(observation);
  if (!OnlyView(observation)) return false;
  Eigen::Vector3d X;
  if (!ProjectorPrediction(p, &X)) return false;
  const int c = camera_index_(observation);
  Eigen::Vector2d pixel;
  if (!ba::ProjectPoint(cameras_[c].K, PoseRotation(poses_, c) * X + PoseTranslation(poses_, c), &pixel, nullptr)) {
    return true;
  }
  return (pixel - observed_.row(observation).transpose()).norm() > options_.pnp_threshold_px;
}

int Reconstruction::AddPoints(int camera) {
  Require(camera >= 0 && camera < num_cameras() && registered_[camera], "add points: camera is not registered");
  int added = 0;
  for (int i : camera_observations_[camera]) {
    const int p = point_index_(i);
    // A point put on the main plane from one view is placed again now that a second
    // camera sees it: it may lie on a table, off that plane.
    const bool again = reconstructed_[p] && single_view_[p];
    if (!active_[i] || (reconstructed_[p] && !again)) continue;
    // Put on the main plane from one view, a point the projector draws elsewhere there
    // would pull the camera towards the pose that sees it where the projector says (a
    // table top's points that only the zoomed camera sees: the or-table room's, 28 deg
    // off). It waits for the refinement's planes.
    if (!again && ProjectorContradictsSingleView(i)) continue;
    if (ReconstructPoint(p)) {
      if (!again) ++added;
    } else if (again) {
      reconstructed_[p] = false;  // its views disagree and cannot be triangulated
    }
  }
  return added;
}

AdjustResult Reconstruction::Adjust(bool final, bool covariance) {
  AdjustResult result;
  const bool coplanar = options_.model == ba::Model::kCoplanar;
  // Observations that take part: active, registered camera, reconstructed point in front.
  std::vector<int> used;
  std::vector<int> point_uses(num_points_, 0);
  const std::vector<Eigen::Matrix3d> rotations = Rotations();
  for (int i = 0; i < static_cast<int>(active_.size()); ++i) {
    if (!active_[i] || !registered_[camera_index_(i)] || !reconstructed_[point_index_(i)]) continue;
    if (!InFront(i, rotations)) {
      active_[i] = false;
      continue;
    }
    used.push_back(i);
    ++point_uses[point_index_(i)];
  }
  // A point on a plane is determined by one view, a point off every plane by two.
  const auto min_uses = [&](int p) { return coplanar && point_plane_[p] >= 0 ? 1 : 2; };
  std::vector<int> camera_map(num_cameras(), -1), point_map(num_points_, -1), cameras, points;
  std::vector<int> kept;
  for (int i : used) {
    const int p = point_index_(i);
    if (point_uses[p] < min_uses(p)) continue;
    const int c = camera_index_(i);
    if (camera_map[c] < 0) {
      camera_map[c] = static_cast<int>(cameras.size());
      cameras.push_back(c);
    }
    if (point_map[p] < 0) {
      point_map[p] = static_cast<int>(points.size());
      points.push_back(p);
    }
    kept.push_back(i);
  }
  for (int p = 0; p < num_points_; ++p) {
    if (reconstructed_[p] && point_map[p] < 0) reconstructed_[p] = false;
  }
  for (int c = 0; c < num_cameras(); ++c) {
    if (registered_[c] && camera_map[c] < 0) {
      registered_[c] = false;
      failure_[c] = "lost all its observations during refinement";
    }
  }
  if (cameras.empty() || kept.empty() || camera_map[gauge_camera_] < 0) return result;

  ba::Data data;
  for (int c : cameras) data.intrinsics.push_back(cameras_[c].K);
  data.poses.resize(cameras.size(), 6);
  for (size_t k = 0; k < cameras.size(); ++k) data.poses.row(k) = poses_.row(cameras[k]);
  data.points.resize(points.size(), 3);
  for (size_t k = 0; k < points.size(); ++k) data.points.row(k) = points_.row(points[k]);
  data.camera_index.resize(kept.size());
  data.point_index.resize(kept.size());
  data.observed.resize(kept.size(), 2);
  for (size_t k = 0; k < kept.size(); ++k) {
    data.camera_index(k) = camera_map[camera_index_(kept[k])];
    data.point_index(k) = point_map[point_index_(kept[k])];
    data.observed.row(k) = observed_.row(kept[k]);
  }
  data.plane = plane_;
  if (coplanar && (!more_planes_.empty() || std::count(point_plane_.begin(), point_plane_.end(), -1) > 0)) {
    data.more_planes.resize(static_cast<int>(more_planes_.size()), 4);
    for (size_t k = 0; k < more_planes_.size(); ++k) data.more_planes.row(k) = more_planes_[k].transpose();
    data.point_plane.resize(static_cast<int>(points.size()));
    for (size_t k = 0; k < points.size(); ++k) data.point_plane(k) = point_plane_[points[k]];
  }
  // Weights: each camera's noise against the median camera's; the projector's noise
  // in the same reference.
  const std::vector<double> sigma = WeightingSigmas();
  std::vector<double> used_sigma;
  for (int c : cameras) used_sigma.push_back(sigma[c]);
  std::nth_element(used_sigma.begin(), used_sigma.begin() + used_sigma.size() / 2, used_sigma.end());
  const double reference_sigma = used_sigma[used_sigma.size() / 2];
  const bool estimated = std::any_of(cameras.begin(), cameras.end(), [&](int c) { return std::isfinite(camera_sigma_px_[c]); });
  if (options_.estimate_noise && estimated && reference_sigma > 0.0) {
    data.camera_weights.resize(static_cast<int>(cameras.size()));
    for (size_t k = 0; k < cameras.size(); ++k) data.camera_weights(k) = reference_sigma / sigma[cameras[k]];
  }
  if (coplanar && relief_on_ && options_.floor_relief > 0.0) {
    const double extent = MainPlaneExtent(points);
    if (extent > 0.0) data.relief_weight = reference_sigma / (options_.floor_relief * extent);
  }
  if (coplanar && HasProjector()) {
    data.projector.resize(static_cast<int>(points.size()), 2);
    for (size_t k = 0; k < points.size(); ++k) data.projector.row(k) = projector_.row(points[k]);
    data.projector_lens = projector_lens_;
    // Each point's term weighs its group's noise against the reference.
    data.projector_weight = projector_width_ * reference_sigma;
    // Not in the test's relief: the apex's three parameters would help it explain what
    // is not a relief.
    if (data.relief_weight > 0.0 && !testing_relief_ && apex_on_) data.apex_prior_px = reference_sigma;
    data.projector_point_weights.resize(static_cast<int>(points.size()));
    for (size_t k = 0; k < points.size(); ++k) {
      const int group = projector_group_[points[k]];
      data.projector_point_weights(k) = group >= 0 ? 1.0 / projector_sigma_px_[group] : 1.0;
    }
  }
  ba::Options ba_options;
  ba_options.model = options_.model;
  ba_options.loss = options_.loss;
  ba_options.loss_scale_px = options_.loss_scale_px;
  if (!final && options_.loss == ba::Loss::kNone) {
    // Before outliers are filtered, a robust loss keeps them from dragging the solution.
    ba_options.loss = ba::Loss::kHuber;
    ba_options.loss_scale_px = options_.pnp_threshold_px;
  }
  ba_options.num_threads = options_.num_threads;
  ba_options.gauge_camera = camera_map[gauge_camera_];
  ba_options.max_iterations = final ? options_.final_ba_iterations : options_.intermediate_ba_iterations;
  if (!final) ba_options.function_tolerance = 1e-6;
  ba_options.compute_covariance = covariance;
  if (covariance) AddLenses(cameras, &data);
  ba_options.error_correlation = options_.error_correlation;
  ba_options.shared_error_shift = options_.shared_error_shift;
  ba_options.shared_error_field = options_.shared_error_field;
  ba_options.relief_cells = testing_relief_ ? std::max(1, options_.relief_cells / kReliefTestCoarsening)
                                            : options_.relief_cells;
  ba_options.relief_cubic = options_.relief_cubic;
  if (cameras.size() < 2 && options_.model == ba::Model::kFree) return result;
  // Without a covariance (the poses not all determined) the solution stands all the same.
  const ba::Result solved = ba::BundleAdjust(data, ba_options);
  if (coplanar && HasProjector()) {
    projector_lens_ = solved.projector_lens;
    projector_surfaces_ = solved.projector_surfaces;
    projector_centre_ = solved.projector_centre;
  }
  if (covariance) {
    StoreCovariances(solved, data, cameras, static_cast<int>(points.size()));
    StoreLensCovariances(solved, data, cameras);
  }
  for (size_t k = 0; k < cameras.size(); ++k) poses_.row(cameras[k]) = solved.poses.row(k);
  for (size_t k = 0; k < points.size(); ++k) points_.row(points[k]) = solved.points.row(k);
  if (coplanar) {
    plane_ = solved.plane;
    for (size_t k = 0; k < more_planes_.size(); ++k) more_planes_[k] = solved.more_planes.row(k).transpose();
  }
  result.initial_cost = solved.initial_cost;
  result.final_cost = solved.final_cost;
  result.observation_cost = solved.final_cost - solved.relief_prior_cost;
  result.reference_sigma_px = reference_sigma > 0.0 ? reference_sigma : 1.0;
  result.relief_nodes = solved.relief_nodes;
  result.iterations = solved.iterations;
  result.termination = solved.termination;
  result.cameras = static_cast<int>(cameras.size());
  result.points = static_cast<int>(points.size());
  result.observations = static_cast<int>(kept.size());
  result.solve_time_s = solved.solve_time_s;
  result.covariance_time_s = solved.covariance_time_s;
  return result;
}

Reconstruction::PixelMatrix Reconstruction::AllResiduals() const {
  PixelMatrix residuals(observed_.rows(), 2);
  residuals.setConstant(std::numeric_limits<double>::quiet_NaN());
  const std::vector<Eigen::Matrix3d> rotations = Rotations();
  for (int i = 0; i < observed_.rows(); ++i) {
    const int c = camera_index_(i), p = point_index_(i);
    if (!registered_[c] || !reconstructed_[p]) continue;
    const Eigen::Vector3d x = rotations[c] * points_.row(p).transpose() + PoseTranslation(poses_, c);
    if (x.z() <= 0.0) continue;
    const ba::Intrinsics& K = cameras_[c].K;
    const double xn = x.x() / x.z(), yn = x.y() / x.z();
    residuals.row(i) << K.fx * xn + K.skew * yn + K.cx - observed_(i, 0), K.fy * yn + K.cy - observed_(i, 1);
  }
  return residuals;
}

Reconstruction::PixelMatrix Reconstruction::Residuals() const {
  PixelMatrix residuals = AllResiduals();
  for (int i = 0; i < residuals.rows(); ++i) {
    if (!active_[i]) residuals.row(i).setConstant(std::numeric_limits<double>::quiet_NaN());
  }
  return residuals;
}

std::vector<double> Reconstruction::OutlierThresholds() const {
  // Sigma from the median of all residuals, outliers included: the median is robust to
  // them, and measuring on clipped residuals would shrink the threshold every round.
  const PixelMatrix residuals = AllResiduals();
  std::vector<std::vector<double>> norms(cameras_.size());
  for (int i = 0; i < residuals.rows(); ++i) {
    if (std::isfinite(residuals(i, 0))) norms[camera_index_(i)].push_back(residuals.row(i).norm());
  }
  std::vector<double> threshold(cameras_.size());
  for (size_t c = 0; c < cameras_.size(); ++c) {
    threshold[c] = std::max(options_.outlier_threshold_px, options_.outlier_sigma_factor * RobustSigma(norms[c]));
  }
  return threshold;
}

int Reconstruction::FilterOutliers() { return FilterOutliers(OutlierThresholds()); }

int Reconstruction::FilterOutliers(const std::vector<double>& threshold) {
  Require(threshold.size() == cameras_.size(), "filter outliers: one threshold per camera is needed");
  // Every observation that can be evaluated is classified again, so one rejected while
  // the solution was still poor comes back once it fits.
  const PixelMatrix residuals = AllResiduals();
  int changed = 0;
  for (int i = 0; i < residuals.rows(); ++i) {
    if (!std::isfinite(residuals(i, 0))) continue;
    const bool inlier = residuals.row(i).norm() <= threshold[camera_index_(i)];
    if (inlier != active_[i]) {
      active_[i] = inlier;
      ++changed;
    }
  }
  return changed;
}

void Reconstruction::StoreCovariances(const ba::Result& solved, const ba::Data& data, const std::vector<int>& cameras,
                                      int points) {
  pose_covariances_.clear();
  pose_covariance_.resize(0, 0);
  pose_lens_covariance_.resize(0, 0);
  lens_covariance_.resize(0, 0);
  covariance_noise_px_.clear();
  if (solved.pose_covariances.size() != cameras.size()) return;
  // Ceres gives the covariance for residuals of unit variance; scale it by the
  // variance the residuals show (per image coordinate).
  int maps = 0;
  for (const auto& surface : solved.projector_surfaces) maps += surface.valid ? 1 : 0;
  const int parameters = 6 * static_cast<int>(cameras.size()) + (options_.model == ba::Model::kCoplanar ? 2 : 3) * points +
                         8 * maps + (maps > 0 ? 2 : 0);
  const int dof = 2 * static_cast<int>(data.camera_index.size()) + 2 * solved.projector_terms - parameters;
  if (dof <= 0) return;
  const double variance = 2.0 * solved.final_cost / dof;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  pose_covariances_.assign(cameras_.size(), ba::Matrix6d::Constant(nan));
  pose_covariance_ = Eigen::MatrixXd::Constant(6 * num_cameras(), 6 * num_cameras(), nan);
  covariance_noise_px_.assign(cameras_.size(), nan);
  for (size_t a = 0; a < cameras.size(); ++a) {
    pose_covariances_[cameras[a]] = variance * solved.pose_covariances[a];
    const double weight = data.camera_weights.size() > 0 ? data.camera_weights(static_cast<int>(a)) : 1.0;
    covariance_noise_px_[cameras[a]] = std::sqrt(variance) / weight;
    for (size_t b = 0; b < cameras.size(); ++b) {
      pose_covariance_.block<6, 6>(6 * cameras[a], 6 * cameras[b]) = variance * solved.pose_covariance.block<6, 6>(6 * a, 6 * b);
    }
  }
}

void Reconstruction::StoreLensCovariances(const ba::Result& solved, const ba::Data& data, const std::vector<int>& cameras) {
  pose_lens_covariance_.resize(0, 0);
  lens_covariance_.resize(0, 0);
  if (pose_covariance_.size() == 0 || solved.lens_sensitivity.size() == 0) return;
  const int C = num_cameras();
  constexpr int L = selfcal::kLensSize;
  std::vector<int> observations(cameras.size(), 0);
  for (int i = 0; i < data.camera_index.size(); ++i) ++observations[data.camera_index(i)];
  // The adjustment's camera k, and where its pose and lens sit in the solve's sensitivity.
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(6 * C, L * C);  // d pose / d lens, every camera
  lens_covariance_ = Eigen::MatrixXd::Zero(L * C, L * C);
  std::vector<double> shared(cameras.size(), 1.0);
  for (size_t k = 0; k < cameras.size(); ++k) {
    const int block = data.lens_block(static_cast<int>(k));
    if (block < 0) continue;
    const int c = cameras[k];
    for (size_t j = 0; j < cameras.size(); ++j) {
      A.block(6 * cameras[j], L * c, 6, L) = solved.lens_sensitivity.block(6 * j, L * block, 6, L);
    }
    // The lens was fitted to the same centres as the poses: their shared errors discount
    // its information as they do the poses' (ba::Options::error_correlation).
    shared[k] = 1.0 + std::max(0, observations[k] - 1) * options_.error_correlation;
    lens_covariance_.block(L * c, L * c, L, L) = shared[k] * lenses_[c]->covariance;
  }
  // Lenses fitted to the same floor points err together (SetLensCrossCovariances).
  for (size_t k = 0; k < cameras.size() && lens_cross_covariance_.size() > 0; ++k) {
    for (size_t j = 0; j < cameras.size(); ++j) {
      if (j == k || data.lens_block(static_cast<int>(k)) < 0 || data.lens_block(static_cast<int>(j)) < 0) continue;
      lens_covariance_.block(L * cameras[k], L * cameras[j], L, L) =
          std::sqrt(shared[k] * shared[j]) * lens_cross_covariance_.block(L * cameras[k], L * cameras[j], L, L);
    }
  }
  // Cameras out of the solve keep their NaN rows; the others gain the lenses' share. The
  // per-camera blocks (pose_covariances(): the sigmas and the weak flag) stay those of
  // the poses given the lenses, what the projection's centres fix.
  pose_lens_covariance_ = A * lens_covariance_;
  const Eigen::MatrixXd from_lenses = pose_lens_covariance_ * A.transpose();
  pose_covariance_ += 0.5 * (from_lenses + from_lenses.transpose());
}

int Reconstruction::FindPlanes() {
  if (options_.model != ba::Model::kCoplanar) return 0;
  // Points off every plane, reconstructed from two views at least.
  std::vector<int> uses(num_points_, 0);
  for (int i = 0; i < static_cast<int>(active_.size()); ++i) {
    if (active_[i] && registered_[camera_index_(i)]) ++uses[point_index_(i)];
  }
  std::vector<int> candidates;
  for (int p = 0; p < num_points_; ++p) {
    if (reconstructed_[p] && point_plane_[p] < 0 && uses[p] >= 2) candidates.push_back(p);
  }
  // Distances are in units of the gauge camera's height above the main plane.
  const double scale = std::abs(plane_(3)) / plane_.head<3>().norm();
  const double threshold = options_.plane_distance * scale;
  // First the points that lie on a plane already known (the floor's points whose views
  // disagreed a little too much, seen at a grazing angle): they go back to it.
  const auto distance_to = [&](const Eigen::Vector4d& plane, int p) {
    return (plane.head<3>().dot(points_.row(p).transpose()) - plane(3)) / plane.head<3>().norm();
  };
  const auto put_on = [&](const Eigen::Vector4d& plane, int index, int p) {
    points_.row(p) -= distance_to(plane, p) * plane.head<3>().transpose() / plane.head<3>().norm();
    point_plane_[p] = index;
  };
  std::vector<int> off;
  for (int p : candidates) {
    if (std::abs(distance_to(plane_, p)) <= threshold) {
      put_on(plane_, 0, p);
    } else {
      off.push_back(p);
    }
  }
  candidates = off;
  std::mt19937_64 rng(options_.seed);
  int found = 0;
  while (static_cast<int>(more_planes_.size()) < options_.max_planes &&
         static_cast<int>(candidates.size()) >= options_.min_plane_points) {
    std::uniform_int_distribution<size_t> pick(0, candidates.size() - 1);
    std::vector<int> best;
    for (int iteration = 0; iteration < options_.ransac_max_iterations; ++iteration) {
      const Eigen::Vector3d a = points_.row(candidates[pick(rng)]).transpose();
      const Eigen::Vector3d b = points_.row(candidates[pick(rng)]).transpose();
      const Eigen::Vector3d c = points_.row(candidates[pick(rng)]).transpose();
      Eigen::Vector3d n = (b - a).cross(c - a);
      if (n.norm() < 1e-12) continue;
      n.normalize();
      std::vector<int> inliers;
      for (int p : candidates) {
        if (std::abs(n.dot(points_.row(p).transpose() - a)) <= threshold) inliers.push_back(p);
      }
      if (inliers.size() > best.size()) best = inliers;
    }
    if (static_cast<int>(best.size()) < options_.min_plane_points) break;
    ba::PointMatrix on_plane(best.size(), 3);
    for (size_t k = 0; k < best.size(); ++k) on_plane.row(k) = points_.row(best[k]);
    const Eigen::Vector4d plane = FitPlaneRobust(on_plane);
    more_planes_.push_back(plane);
    const int index = static_cast<int>(more_planes_.size());
    std::vector<int> rest;
    for (int p : candidates) {
      if (std::abs(distance_to(plane, p)) <= threshold) {
        put_on(plane, index, p);
      } else {
        rest.push_back(p);
      }
    }
    candidates = rest;
    ++found;
  }
  OutlineSurfaces();
  PlaceSingleViewPointsOnTheirSurfaces();
  return found;
}

void Reconstruction::PlaceSingleViewPointsOnTheirSurfaces() {
  // A point one camera alone sees was put on the main plane. Across one plane, the map
  // from projector pixels to a camera's pixels is a homography, different per plane
  // wherever the camera is not at the projector: the plane whose homography (fitted to
  // the camera's points placed by other cameras too) explains the point is the one it
  // lies on (a table top only a zoomed camera sees there).
  if (!HasProjector()) return;
  for (int c = 0; c < num_cameras(); ++c) {
    if (!registered_[c]) continue;
    std::vector<std::vector<cv::Point2d>> from(more_planes_.size() + 1), to(more_planes_.size() + 1);
    std::vector<int> single, waiting;
    for (const int i : camera_observations_[c]) {
      const int p = point_index_(i);
      if (!active_[i] || !projector_.row(p).allFinite()) continue;
      if (!reconstructed_[p]) {
        if (OnlyView(i)) waiting.push_back(i);
      } else if (single_view_[p]) {
        single.push_back(i);
      } else if (point_plane_[p] >= 0) {
        from[point_plane_[p]].emplace_back(projector_(p, 0), projector_(p, 1));
        to[point_plane_[p]].emplace_back(observed_(i, 0), observed_(i, 1));
      }
    }
    if (single.empty() && waiting.empty()) continue;
    std::vector<cv::Mat> maps(from.size());
    for (size_t k = 0; k < from.size(); ++k) {
      if (static_cast<int>(from[k].size()) >= kMinPlaneMapPoints) maps[k] = cv::findHomography(from[k], to[k], 0);
    }
    const auto explaining = [&](int i) {
      return PlaneExplaining(maps, {projector_(point_index_(i), 0), projector_(point_index_(i), 1)},
                             {observed_(i, 0), observed_(i, 1)});
    };
    for (const int i : single) {
      const int p = point_index_(i);
      const int plane = explaining(i);
      if (plane < 0 || plane == point_plane_[p]) continue;
      if (!ReconstructPoint(p, plane)) reconstructed_[p] = false;
    }
    for (const int i : waiting) ReconstructPoint(point_index_(i), std::max(explaining(i), 0));
  }
}

std::string ReliefTest::Describe() const {
  if (!tested) return "";
  char figures[200];
  std::snprintf(figures, sizeof figures,
                " (the relief takes %.1f off the chi-square, %.1f would be errors the cameras share over its %d nodes)",
                gain_chi2, threshold_chi2, nodes);
  const char* verdict = !detected ? "floor flat within the noise: kept exactly flat"
                        : parallax ? "floor uneven: its relief is estimated, and the projector's place from its parallax"
                                   : "floor uneven: its relief is estimated";
  return verdict + std::string(figures);
}

ReliefTest Reconstruction::TestRelief() {
  ReliefTest test;
  if (options_.model != ba::Model::kCoplanar || options_.floor_relief <= 0.0) return test;
  // Both solves start from the same geometry: a relief's solve may end where the flat
  // one does not come back from (the or-table room: every camera 0.8 deg off, the
  // zoomed one 37 deg, where the flat solve from the registered geometry is right).
  const ba::PoseMatrix poses = poses_;
  const ba::PointMatrix points = points_;
  const Eigen::Vector4d plane = plane_;
  const std::vector<Eigen::Vector4d> more_planes = more_planes_;
  const Eigen::Vector2d projector_lens = projector_lens_;
  const std::vector<ba::ProjectorSurface> projector_surfaces = projector_surfaces_;
  const Eigen::Vector3d projector_centre = projector_centre_;
  relief_on_ = true;
  testing_relief_ = true;
  const AdjustResult uneven = Adjust(true);
  testing_relief_ = false;
  poses_ = poses;
  points_ = points;
  plane_ = plane;
  more_planes_ = more_planes;
  projector_lens_ = projector_lens;
  projector_surfaces_ = projector_surfaces;
  projector_centre_ = projector_centre;
  if (uneven.relief_nodes == 0) return test;
  relief_on_ = false;
  const AdjustResult flat = Adjust(true);
  test.tested = true;
  test.nodes = uneven.relief_nodes;
  // Both solves weigh the observations alike, so twice the cost difference over the
  // reference noise squared is the likelihood ratio's chi-square.
  const double unit = uneven.reference_sigma_px * uneven.reference_sigma_px;
  test.gain_chi2 = std::max(0.0, 2.0 * (flat.observation_cost - uneven.observation_cost) / unit);
  const double noise_quantile = ChiSquareQuantile(test.nodes, kReliefTestZ);
  test.threshold_chi2 = kReliefSharedErrorFactor * noise_quantile;
  test.detected = test.gain_chi2 > test.threshold_chi2;
  relief_on_ = test.detected;
  apex_on_ = test.gain_chi2 > kApexGainFactor * noise_quantile;
  test.parallax = apex_on_;
  return test;
}

RefineResult Reconstruction::Refine() {
  const auto start = std::chrono::steady_clock::now();
  RefineResult result;
  pose_covariances_.clear();
  pose_covariance_.resize(0, 0);
  pose_lens_covariance_.resize(0, 0);
  lens_covariance_.resize(0, 0);
  covariance_noise_px_.clear();
  const auto placed = [&] { return std::count(reconstructed_.begin(), reconstructed_.end(), true); };
  const auto before_planes = placed();
  result.planes_found = FindPlanes();
  if (placed() > before_planes) {
    // Points placed for the first time (AddPoints left them for the planes) join as
    // the registration's do, through a robust adjustment and the outlier filter: the
    // relief test weighs every residual as it is (or-table room, a gross outlier among
    // them: a relief detected on the flat floor at 2,600 times its bar).
    Adjust(false);
    FilterOutliers();
  }
  result.relief = TestRelief();
  for (int round = 0; round < options_.max_refine_rounds; ++round) {
    // The covariance of every round (cheap: the reduced camera system): the last one
    // stands, its weights settled.
    result.last = Adjust(true, true);
    result.covariance_seconds += result.last.covariance_time_s;
    ++result.rounds;
    const std::vector<double> before = camera_sigma_px_;
    const std::vector<double> projector_before = projector_sigma_px_;
    EstimateNoise();
    result.thresholds = OutlierThresholds();
    const int changed = FilterOutliers(result.thresholds);
    result.changed += changed;
    if (changed == 0 && NoiseSettled(before, projector_before)) {
      break;
    }
  }
  result.removed = static_cast<int>(std::count(active_.begin(), active_.end(), false));
  CheckPlanarAmbiguity();
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

void Reconstruction::CheckPlanarAmbiguity() {
  // A camera that sees a small patch of one plane nearly affinely fits two poses, mirror
  // images about its line of sight (the planar PnP ambiguity). When the images cannot
  // tell them apart at its noise, the angle between them is how well its rotation is
  // known, whatever the covariance of the chosen one says.
  ambiguity_deg_.assign(cameras_.size(), 0.0);
  const std::vector<double> sigma = WeightingSigmas();
  for (int c = 0; c < num_cameras(); ++c) {
    if (!registered_[c] || c == gauge_camera_) continue;
    // The points as the other cameras and the projector place them: this camera's
    // own pose has pulled the ones it alone sees.
    std::vector<cv::Point3d> object;
    std::vector<cv::Point2d> image;
    for (int i : camera_observations_[c]) {
      const int p = point_index_(i);
      if (!active_[i] || !reconstructed_[p] || point_plane_[p] != 0) continue;
      Eigen::Vector3d X = points_.row(p).transpose();
      ProjectorPrediction(p, &X);
      object.emplace_back(X.x(), X.y(), X.z());
      image.emplace_back(observed_(i, 0), observed_(i, 1));
    }
    const std::vector<PlanarPose> poses = PlanarPoses(object, image, cameras_[c].K);
    if (poses.size() < 2) continue;
    const double n = static_cast<double>(object.size());
    const double evidence =
        n * (poses[1].rms_px * poses[1].rms_px - poses[0].rms_px * poses[0].rms_px) / (sigma[c] * sigma[c]);
    if (!(evidence < kAmbiguityEvidence)) continue;
    const double cosine = std::clamp(((poses[0].R.transpose() * poses[1].R).trace() - 1.0) / 2.0, -1.0, 1.0);
    ambiguity_deg_[c] = std::acos(cosine) * 180.0 / M_PI;
  }
}

std::vector<double> Reconstruction::WeightingSigmas() const {
  // Until a camera's own noise is estimated it gets the pooled one: its residuals alone
  // understate it, the more so the more its centres determine their points.
  const PixelMatrix residuals = Residuals();
  std::vector<double> norms;
  for (int i = 0; i < residuals.rows(); ++i) {
    if (std::isfinite(residuals(i, 0))) norms.push_back(residuals.row(i).norm());
  }
  const double pooled = std::max(RobustSigma(norms), kMinNoisePx);
  std::vector<double> sigma(cameras_.size(), pooled);
  for (size_t c = 0; c < cameras_.size(); ++c) {
    if (std::isfinite(camera_sigma_px_[c])) sigma[c] = camera_sigma_px_[c];
  }
  return sigma;
}

bool Reconstruction::NoiseSettled(const std::vector<double>& before,
                                  const std::vector<double>& projector_before) const {
  if (!options_.estimate_noise) return true;
  const auto close = [](double a, double b) {
    return (!std::isfinite(a) && !std::isfinite(b)) || std::abs(a - b) <= 0.05 * std::max(std::abs(a), std::abs(b));
  };
  for (size_t c = 0; c < before.size(); ++c) {
    if (!close(before[c], camera_sigma_px_[c])) return false;
  }
  for (size_t g = 0; g < projector_before.size(); ++g) {
    if (!close(projector_before[g], projector_sigma_px_[g])) return false;
  }
  return true;
}

void Reconstruction::EstimateNoise() {
  if (!options_.estimate_noise) return;
  std::vector<ba::Intrinsics> intrinsics;
  for (const Camera& camera : cameras_) intrinsics.push_back(camera.K);
  std::vector<Eigen::Vector4d> planes = {plane_};
  planes.insert(planes.end(), more_planes_.begin(), more_planes_.end());
  NoiseInputs in;
  in.intrinsics = &intrinsics;
  in.poses = &poses_;
  in.points = &points_;
  in.registered = &registered_;
  in.reconstructed = &reconstructed_;
  in.active = &active_;
  in.camera_index = &camera_index_;
  in.point_index = &point_index_;
  in.observed = &observed_;
  in.point_plane = &point_plane_;
  in.planes = &planes;
  if (HasProjector()) {
    in.projector = &projector_;
    in.lens = projector_lens_;
    in.surfaces = &projector_surfaces_;
    in.projector_width = projector_width_;
    in.projector_group = &projector_group_;
  }
  in.gauge_camera = gauge_camera_;
  // The residuals do not change between steps: the weights of cameras without an
  // estimate (the robust sigma of all residuals) are computed once.
  const std::vector<double> start = WeightingSigmas();
  const auto current = [&] {
    std::vector<double> sigma = start;
    for (size_t c = 0; c < sigma.size(); ++c) {
      if (std::isfinite(camera_sigma_px_[c])) sigma[c] = camera_sigma_px_[c];
    }
    return sigma;
  };
  in.camera_sigma_px = start;
  in.projector_sigma_px = projector_sigma_px_;
  // To the fixed point under the adjustment's poses and maps (the points re-placed at
  // each step); the next adjustment then starts from weights that hold.
  const NoiseProblem problem(in);
  // The first estimate gives every projector group the noise of all: a group whose
  // points one camera mostly sees splits their residuals with that camera almost
  // freely, and from unequal starting weights the iteration can settle on a split that
  // blames either for all (seen: a zoomed camera at 0.5 px where its centres are good
  // to 0.02). Later estimates start from where all groups agreed.
  const bool pool_projector = !projector_sigma_estimated_;
  for (int step = 0; step < kNoiseSteps; ++step) {
    const std::vector<double> before = in.camera_sigma_px;
    const std::vector<double> projector_before = in.projector_sigma_px;
    if (!UpdateNoise(problem.Estimate(in.camera_sigma_px, in.projector_sigma_px), pool_projector)) return;
    in.camera_sigma_px = current();
    in.projector_sigma_px = projector_sigma_px_;
    double change = 0.0;
    for (size_t g = 0; g < projector_before.size(); ++g) {
      change = std::max(change, std::abs(projector_before[g] - in.projector_sigma_px[g]) /
                                    std::max(projector_before[g], 1e-12));
    }
    for (size_t c = 0; c < before.size(); ++c) {
      change = std::max(change, std::abs(before[c] - in.camera_sigma_px[c]) / std::max(before[c], 1e-12));
    }
    if (change < kNoiseStepTolerance) break;
  }
}

bool Reconstruction::UpdateNoise(const NoiseEstimate& estimate, bool pool_projector) {
  // The pooled noise: the median of the cameras whose residuals tell it well.
  std::vector<double> reliable;
  for (int c = 0; c < num_cameras(); ++c) {
    if (std::isfinite(estimate.camera_sigma_px[c]) && estimate.camera_redundancy[c] >= kPriorRedundancy) {
      reliable.push_back(estimate.camera_sigma_px[c]);
    }
  }
  if (reliable.empty()) return false;
  std::nth_element(reliable.begin(), reliable.begin() + reliable.size() / 2, reliable.end());
  const double pooled = reliable[reliable.size() / 2];
  for (int c = 0; c < num_cameras(); ++c) {
    if (!registered_[c]) continue;
    // A camera with little redundancy is drawn towards the pooled noise, as if the pooled
    // value came from kPriorRedundancy observations of its own.
    const double r = std::max(estimate.camera_redundancy[c], 0.0);
    const double own = std::isfinite(estimate.camera_sigma_px[c]) ? estimate.camera_sigma_px[c] : pooled;
    const double variance = (r * own * own + kPriorRedundancy * pooled * pooled) / (r + kPriorRedundancy);
    camera_sigma_px_[c] = std::max(std::sqrt(variance), kMinNoisePx);
  }
  const double pooled_projector = estimate.pooled_projector_sigma_px;
  if (std::isfinite(pooled_projector) && estimate.projector_sigma_px.size() == projector_sigma_px_.size()) {
    // A group with little redundancy is drawn towards all groups' noise, as cameras are.
    for (size_t g = 0; g < projector_sigma_px_.size(); ++g) {
      const double r = std::max(estimate.projector_redundancy[g], 0.0);
      const double own = std::isfinite(estimate.projector_sigma_px[g]) && !pool_projector
                             ? estimate.projector_sigma_px[g]
                             : pooled_projector;
      const double variance =
          (r * own * own + kPriorRedundancy * pooled_projector * pooled_projector) / (r + kPriorRedundancy);
      projector_sigma_px_[g] = std::max(std::sqrt(variance), kMinProjectorNoisePx);
    }
    projector_sigma_estimated_ = true;
  }
  return true;
}

void Reconstruction::FailUnregistered() {
  int observing = 0;
  for (int c = 0; c < num_cameras(); ++c) observing += camera_observations_[c].empty() ? 0 : 1;
  for (int c = 0; c < num_cameras(); ++c) {
    if (registered_[c] || !failure_[c].empty()) continue;
    int shared = 0;
    Eigen::Vector3d X;
    for (int i : camera_observations_[c]) {
      if (active_[i] && KnownPoint(point_index_(i), &X)) ++shared;
    }
    if (camera_observations_[c].empty()) {
      failure_[c] = "no observations";
    } else if (observing == 1) {
      failure_[c] = "the only camera with observations (a calibration needs two or more cameras that see "
                    "common points)";
    } else if (shared == 0) {
      failure_[c] = "no point in common with the registered cameras (disconnected)";
    } else {
      failure_[c] = "only " + Str(shared) + " points in common with the registered cameras (need " +
                    Str(MinPnpPoints()) + ")";
    }
  }
}

}  // namespace calibproj::registration
