#include "calibproj/check/camera_check.h"

#include <ceres/autodiff_cost_function.h>
#include <ceres/problem.h>
#include <ceres/rotation.h>
#include <ceres/solver.h>

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <vector>

#include "calibproj/common/limits.h"
#include "calibproj/common/quantile.h"
#include "calibproj/detect/lens.h"

namespace calibproj::check {

namespace {

constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;
// The noise never taken below this (px): a fit to a few exact points would otherwise
// call any change significant.
constexpr double kMinNoisePx = 0.01;
// Inlier selection rounds (fit, keep the observations near it, fit again).
constexpr int kInlierRounds = 3;

// The stored lens distortion, in a fixed layout (k1, k2, p1, p2, k3, k4, k5, k6,
// s1, s2, s3, s4).
struct Lens {
  bool distorted = false;
  double coefficients[12] = {};
};

Lens LensOf(const std::vector<double>& dist) {
  if (dist.size() > 12) {
    throw std::invalid_argument("check: a distortion of " + std::to_string(dist.size()) +
                                " coefficients (a tilted sensor) is not supported");
  }
  Lens lens;
  for (std::size_t k = 0; k < dist.size(); ++k) {
    if (!std::isfinite(dist[k])) throw std::invalid_argument("check: the distortion is not finite");
    lens.coefficients[k] = dist[k];
    lens.distorted |= dist[k] != 0.0;
  }
  return lens;
}

// Undistorted pixels (of K) back to the distorted pixels they were made from.
Eigen::Matrix2Xd Distorted(const ba::Intrinsics& K, const std::vector<double>& dist, const Eigen::Matrix2Xd& pixels) {
  if (pixels.cols() == 0) return pixels;
  formats::CameraIntrinsics model;
  model.K << K.fx, K.skew, K.cx, 0.0, K.fy, K.cy, 0.0, 0.0, 1.0;
  model.dist = dist;
  std::vector<cv::Point2d> points(pixels.cols());
  for (int i = 0; i < pixels.cols(); ++i) points[i] = {pixels(0, i), pixels(1, i)};
  const std::vector<cv::Point2d> distorted = detect::DistortPixels(model, points);
  Eigen::Matrix2Xd out(2, pixels.cols());
  for (int i = 0; i < pixels.cols(); ++i) out.col(i) << distorted[i].x, distorted[i].y;
  return out;
}

// Which of the camera's parameters a fit frees.
enum class Freed { kPose, kFocal, kBoth };

// OpenCV's distortion of normalized coordinates (k1, k2, p1, p2, k3, k4, k5, k6, s1..s4;
// missing ones 0): what cv::projectPoints applies, for the focal fits.
template <typename T>
void Distort(const Lens& lens, const T& x, const T& y, T* xd, T* yd) {
  const double* d = lens.coefficients;
  const T r2 = x * x + y * y, r4 = r2 * r2, r6 = r4 * r2;
  const T radial = (T(1.0) + T(d[0]) * r2 + T(d[1]) * r4 + T(d[4]) * r6) /
                   (T(1.0) + T(d[5]) * r2 + T(d[6]) * r4 + T(d[7]) * r6);
  *xd = x * radial + T(2.0 * d[2]) * x * y + T(d[3]) * (r2 + T(2.0) * x * x) + T(d[8]) * r2 + T(d[9]) * r4;
  *yd = y * radial + T(d[2]) * (r2 + T(2.0) * y * y) + T(2.0 * d[3]) * x * y + T(d[10]) * r2 + T(d[11]) * r4;
}

// One observation of a held point: x_cam = exp(w) R_stored (X - c), pixel through the
// lens with the focal lengths (and skew) scaled by s about the principal point. The
// observation is in distorted pixels when the lens has distortion: a re-zoomed camera's
// pixels undistorted with its stored focal length are no pinhole image of its new one.
struct HeldPointResidual {
  HeldPointResidual(const ba::Intrinsics& K, const Lens& lens, const Eigen::Matrix3d& R_stored,
                    const Eigen::Vector3d& X, const Eigen::Vector2d& observed)
      : K_(K), lens_(lens), observed_(observed) {
    // The stored rotation applied once: only the update is a parameter.
    Eigen::Map<Eigen::Vector3d>(rotated_, 3) = R_stored * X;
    Eigen::Map<Eigen::Matrix3d>(R_, 3, 3) = R_stored;
  }

  template <typename T>
  bool operator()(const T* w, const T* c, const T* s, T* residual) const {
    T relative[3];
    for (int i = 0; i < 3; ++i) {
      relative[i] = T(rotated_[i]) - (T(R_[i]) * c[0] + T(R_[i + 3]) * c[1] + T(R_[i + 6]) * c[2]);
    }
    T p[3];
    ceres::AngleAxisRotatePoint(w, relative, p);
    if (!(p[2] > T(ba::kMinDepth))) return false;
    T xn = p[0] / p[2];
    T yn = p[1] / p[2];
    if (lens_.distorted) {
      const T x = xn, y = yn;
      Distort(lens_, x, y, &xn, &yn);
    }
    residual[0] = s[0] * (T(K_.fx) * xn + T(K_.skew) * yn) + T(K_.cx) - T(observed_.x());
    residual[1] = s[0] * T(K_.fy) * yn + T(K_.cy) - T(observed_.y());
    return true;
  }

  ba::Intrinsics K_;
  Lens lens_;
  Eigen::Vector2d observed_;
  double rotated_[3];
  double R_[9];  // column-major
};

struct Fit {
  double w[3] = {0.0, 0.0, 0.0};
  double c[3] = {0.0, 0.0, 0.0};
  double s = 1.0;
  double ssr = 0.0;  // sum of squared residuals (px^2) over the fitted observations
  bool converged = false;
  Eigen::MatrixXd information;  // J^T J of the freed parameters (w, c, s order), unscaled
};

Eigen::Vector3d Centre(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) { return -R.transpose() * t; }

// One set of observations of held points by the camera (the new ones, or those the
// stored calibration was made from), with the stored camera they are fitted from.
struct Observations {
  const ba::Intrinsics& K;
  const Lens& lens;
  const Eigen::Matrix3d& R;  // stored rotation: the fits are updates of it
  const Eigen::Matrix3Xd& points;
  const Eigen::Matrix2Xd& observed;  // distorted pixels when the lens has distortion
  int size() const { return static_cast<int>(points.cols()); }
};

Fit Solve(const Observations& input, const std::vector<int>& used, Freed freed, const Fit& start,
          const CheckOptions& options) {
  Fit fit = start;
  ceres::Problem problem;
  for (int i : used) {
    auto* cost = new ceres::AutoDiffCostFunction<HeldPointResidual, 2, 3, 3, 1>(
        new HeldPointResidual(input.K, input.lens, input.R, input.points.col(i), input.observed.col(i)));
    problem.AddResidualBlock(cost, nullptr, fit.w, fit.c, &fit.s);
  }
  if (freed == Freed::kFocal) {
    problem.SetParameterBlockConstant(fit.w);
    problem.SetParameterBlockConstant(fit.c);
  }
  if (freed == Freed::kPose) problem.SetParameterBlockConstant(&fit.s);
  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::DENSE_QR;
  solver.max_num_iterations = options.max_iterations;
  solver.num_threads = 1;
  solver.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  fit.converged = summary.IsSolutionUsable();
  fit.ssr = 2.0 * summary.final_cost;
  // The information of the freed parameters, from the Jacobian at the solution.
  ceres::CRSMatrix jacobian;
  problem.Evaluate(ceres::Problem::EvaluateOptions(), nullptr, nullptr, nullptr, &jacobian);
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(jacobian.num_rows, jacobian.num_cols);
  for (int row = 0; row < jacobian.num_rows; ++row) {
    for (int k = jacobian.rows[row]; k < jacobian.rows[row + 1]; ++k) J(row, jacobian.cols[k]) = jacobian.values[k];
  }
  fit.information = J.transpose() * J;
  return fit;
}

// The inverse of an information matrix whose parameters differ in scale by orders of
// magnitude (radians, world units, a focal ratio): equilibrated first, so that the
// weakly determined direction of a narrow camera (rotation against centre) keeps its
// large variance instead of being cut off as numerically null.
Eigen::MatrixXd Inverse(const Eigen::MatrixXd& information) {
  const Eigen::VectorXd scale = information.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  const Eigen::MatrixXd balanced = scale.asDiagonal() * information * scale.asDiagonal();
  const Eigen::MatrixXd inverse = balanced.ldlt().solve(Eigen::MatrixXd::Identity(balanced.rows(), balanced.cols()));
  return scale.asDiagonal() * inverse * scale.asDiagonal();
}

// The covariance of the parameters a fit frees, the others held (zero rows and columns),
// from the information of all seven at the solution.
Eigen::Matrix<double, 7, 7> CovarianceOf(const Eigen::MatrixXd& information, Freed freed) {
  Eigen::Matrix<double, 7, 7> covariance = Eigen::Matrix<double, 7, 7>::Zero();
  if (freed == Freed::kBoth) return Inverse(information);
  if (freed == Freed::kPose) {
    covariance.topLeftCorner<6, 6>() = Inverse(information.topLeftCorner(6, 6));
  } else {
    covariance(6, 6) = information(6, 6) > 0.0 ? 1.0 / information(6, 6) : std::numeric_limits<double>::infinity();
  }
  return covariance;
}

Eigen::Vector2d Residual(const Observations& input, const Fit& fit, int i) {
  const HeldPointResidual cost(input.K, input.lens, input.R, input.points.col(i), input.observed.col(i));
  double r[2] = {1e9, 1e9};
  if (!cost(fit.w, fit.c, &fit.s, r)) return {1e9, 1e9};
  return {r[0], r[1]};
}

double SumSquares(const Observations& input, const Fit& fit, const std::vector<int>& used) {
  double sum = 0.0;
  for (int i : used) sum += Residual(input, fit, i).squaredNorm();
  return sum;
}

// The fit of pose and focal length together and the observations near it, from plain
// least squares (a moved zoomed camera starts hundreds of pixels off, where a robust
// loss has no gradient left), dropping those beyond outlier_px and fitting again.
Fit RobustFit(const Observations& input, const Fit& start, const CheckOptions& options, std::vector<int>* used) {
  used->resize(input.size());
  for (int i = 0; i < input.size(); ++i) (*used)[i] = i;
  for (int round = 0; round < kInlierRounds; ++round) {
    const Fit both = Solve(input, *used, Freed::kBoth, start, options);
    std::vector<int> kept;
    for (int i = 0; i < input.size(); ++i) {
      if (Residual(input, both, i).norm() <= options.outlier_px) kept.push_back(i);
    }
    if (kept == *used) return both;
    *used = kept;
    if (static_cast<int>(used->size()) < options.min_points) return both;  // too few: the caller says so
  }
  // The fit always describes the observations kept.
  return Solve(input, *used, Freed::kBoth, start, options);
}

double NoiseOf(const Fit& fit, int observations) {
  return std::max(kMinNoisePx, std::sqrt(fit.ssr / std::max(1, 2 * observations - 7)));
}

Eigen::Matrix3d RotationOf(const double* w, const Eigen::Matrix3d& stored) {
  Eigen::Matrix3d update;
  ceres::AngleAxisToRotationMatrix(w, ceres::ColumnMajorAdapter3x3(update.data()));
  return update * stored;
}

// Pixel of X for the camera (R, t) with K's focal part scaled by s; false behind it.
bool Project(const ba::Intrinsics& K, const Eigen::Matrix3d& R, const Eigen::Vector3d& t, double s,
             const Eigen::Vector3d& X, Eigen::Vector2d* pixel) {
  const Eigen::Vector3d p = R * X + t;
  if (!(p.z() > ba::kMinDepth)) return false;
  const double xn = p.x() / p.z(), yn = p.y() / p.z();
  *pixel << s * (K.fx * xn + K.skew * yn) + K.cx, s * K.fy * yn + K.cy;
  return true;
}

// A camera as a fit gives it: rotation, translation and focal scale.
struct Pinhole {
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  double s = 1.0;
};

Pinhole PinholeOf(const Fit& fit, const Eigen::Matrix3d& stored) {
  const Eigen::Matrix3d R = RotationOf(fit.w, stored);
  return {R, -R * Eigen::Vector3d(fit.c[0], fit.c[1], fit.c[2]), fit.s};
}

// Largest move in the image, from camera `before` to `after`, of a working-volume point
// the stored camera sees (of the observed points when none of the volume is in view).
double VolumeShift(const CameraCheckInput& input, const Pinhole& before, const Pinhole& after) {
  const auto largest = [&](const Eigen::Matrix3Xd& points, bool inside_only) {
    double shift = -1.0;
    for (int i = 0; i < points.cols(); ++i) {
      Eigen::Vector2d seen, from, to;
      if (!Project(input.K, input.R, input.t, 1.0, points.col(i), &seen)) continue;
      if (inside_only && !(seen.x() >= 0 && seen.y() >= 0 && seen.x() <= input.width && seen.y() <= input.height)) {
        continue;
      }
      if (!Project(input.K, before.R, before.t, before.s, points.col(i), &from) ||
          !Project(input.K, after.R, after.t, after.s, points.col(i), &to)) {
        continue;
      }
      shift = std::max(shift, (to - from).norm());
    }
    return shift;
  };
  const double shift = largest(input.volume, input.width > 0 && input.height > 0);
  return shift >= 0.0 ? shift : std::max(0.0, largest(input.points, false));
}

// The volume points the stored camera sees in its image (all of them without its size).
std::vector<int> VolumeInView(const CameraCheckInput& input) {
  const bool sized = input.width > 0 && input.height > 0;
  std::vector<int> inside;
  for (int i = 0; i < input.volume.cols(); ++i) {
    Eigen::Vector2d seen;
    if (!Project(input.K, input.R, input.t, 1.0, input.volume.col(i), &seen)) continue;
    if (sized && !(seen.x() >= 0 && seen.y() >= 0 && seen.x() <= input.width && seen.y() <= input.height)) continue;
    inside.push_back(i);
  }
  return inside;
}

// d pixel / d (w, c, s) of X at the stored camera (central differences: the pixel is
// smooth and the steps far above rounding).
Eigen::Matrix<double, 2, 7> PixelJacobian(const CameraCheckInput& input, const Eigen::Vector3d& X) {
  const Eigen::Vector3d centre = Centre(input.R, input.t);
  const double steps[7] = {1e-6, 1e-6, 1e-6, 1e-6 * (1.0 + centre.norm()), 1e-6 * (1.0 + centre.norm()),
                           1e-6 * (1.0 + centre.norm()), 1e-6};
  Eigen::Matrix<double, 2, 7> J = Eigen::Matrix<double, 2, 7>::Zero();
  for (int k = 0; k < 7; ++k) {
    Eigen::Vector2d ends[2];
    for (int side = 0; side < 2; ++side) {
      Fit fit;
      std::copy(centre.data(), centre.data() + 3, fit.c);
      const double step = side == 0 ? steps[k] : -steps[k];
      if (k < 3) fit.w[k] = step;
      if (k >= 3 && k < 6) fit.c[k - 3] += step;
      if (k == 6) fit.s += step;
      const Pinhole camera = PinholeOf(fit, input.R);
      if (!Project(input.K, camera.R, camera.t, camera.s, X, &ends[side])) return J;
    }
    J.col(k) = (ends[0] - ends[1]) / (2.0 * steps[k]);
  }
  return J;
}

// The farthest a pixel of the image (or, without its size, an observation) lies from
// the principal point: how far a focal change of 1 moves a pixel at most.
double LargestRadius(const CameraCheckInput& input) {
  double radius = 0.0;
  if (input.width > 0 && input.height > 0) {
    for (const double x : {0.0, input.width}) {
      for (const double y : {0.0, input.height}) radius = std::max(radius, std::hypot(x - input.K.cx, y - input.K.cy));
    }
    return radius;
  }
  for (int i = 0; i < input.observed.cols(); ++i) {
    radius = std::max(radius, std::hypot(input.observed(0, i) - input.K.cx, input.observed(1, i) - input.K.cy));
  }
  return radius;
}

void CheckInput(const CameraCheckInput& input) {
  if (input.points.cols() != input.observed.cols()) {
    throw std::invalid_argument("check: points and observations differ in number (" +
                                std::to_string(input.points.cols()) + " and " + std::to_string(input.observed.cols()) +
                                ")");
  }
  if (input.reference_points.cols() != input.reference_observed.cols()) {
    throw std::invalid_argument("check: the reference points and observations differ in number (" +
                                std::to_string(input.reference_points.cols()) + " and " +
                                std::to_string(input.reference_observed.cols()) + ")");
  }
  if (!input.points.allFinite() || !input.observed.allFinite() || !input.volume.allFinite() ||
      !input.reference_points.allFinite() || !input.reference_observed.allFinite()) {
    throw std::invalid_argument("check: points, observations and volume must be finite");
  }
  if (!input.R.allFinite() || !input.t.allFinite()) throw std::invalid_argument("check: the stored pose is not finite");
  limits::RequireInRange(input.K.fx, 1e-9, limits::kMaxMagnitude, "check: fx");
  limits::RequireInRange(input.K.fy, 1e-9, limits::kMaxMagnitude, "check: fy");
  limits::RequireInRange(input.rotation_sigma, 0.0, 10.0, "check: rotation_sigma");
  limits::RequireInRange(input.centre_sigma, 0.0, limits::kMaxMagnitude, "check: centre_sigma");
  limits::RequireInRange(input.width, 0.0, limits::kMaxImageSide, "check: width");
  limits::RequireInRange(input.height, 0.0, limits::kMaxImageSide, "check: height");
}

std::string Figures(const char* format, double a, double b = 0.0, double c = 0.0, double d = 0.0,
                    double e = 0.0) {
  char text[240];
  std::snprintf(text, sizeof text, format, a, b, c, d, e);
  return text;
}

}  // namespace

void CheckOptions::Check() const {
  limits::RequireInRange(tolerance_px, 0.0, 1e6, "check: tolerance_px");
  limits::RequireInRange(significance_z, 0.0, 40.0, "check: significance_z");
  limits::RequireInRange(min_points, 6, limits::kMaxPoints, "check: min_points");
  limits::RequireInRange(outlier_px, 1e-3, 1e6, "check: outlier_px");
  limits::RequireInRange(model_error_px, 0.0, 1e3, "check: model_error_px");
  limits::RequireInRange(max_iterations, 1, limits::kMaxIterations, "check: max_iterations");
}

const char* StatusName(Status status) {
  switch (status) {
    case Status::kUnchanged: return "unchanged";
    case Status::kMoved: return "moved";
    case Status::kRezoomed: return "rezoomed";
    case Status::kUnknown: return "unknown";
  }
  return "unknown";
}

double VolumeShiftSigma(const CameraCheckInput& input, const Eigen::Matrix<double, 7, 7>& covariance) {
  double sigma = 0.0;
  for (const int i : VolumeInView(input)) {
    const Eigen::Matrix<double, 2, 7> J = PixelJacobian(input, input.volume.col(i));
    const Eigen::Matrix2d image = J * covariance * J.transpose();
    sigma = std::max(sigma, std::sqrt(std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(image)
                                                         .eigenvalues()
                                                         .maxCoeff())));
  }
  return sigma;
}

double PredictedShiftSigma(const CameraCheckInput& input, double noise_px) {
  limits::RequireInRange(noise_px, 1e-6, 1e3, "check: noise_px");
  CheckInput(input);
  if (input.points.cols() < 6) return std::numeric_limits<double>::infinity();
  Eigen::MatrixXd information = Eigen::MatrixXd::Zero(7, 7);
  for (int i = 0; i < input.points.cols(); ++i) {
    const Eigen::Matrix<double, 2, 7> J = PixelJacobian(input, input.points.col(i));
    information += J.transpose() * J;
  }
  // A camera the points do not fix (collinear, all behind it) resolves nothing.
  const Eigen::Matrix<double, 7, 7> covariance = CovarianceOf(information, Freed::kBoth) * (noise_px * noise_px);
  if (!covariance.allFinite() || Eigen::FullPivLU<Eigen::MatrixXd>(information).rank() < 7) {
    return std::numeric_limits<double>::infinity();
  }
  return VolumeShiftSigma(input, covariance);
}

CameraCheck CheckCamera(const CameraCheckInput& input, const CheckOptions& options) {
  options.Check();
  CheckInput(input);
  CameraCheck out;
  out.R = input.R;
  out.t = input.t;
  out.points = static_cast<int>(input.points.cols());
  if (out.points < options.min_points) {
    out.reason = "only " + std::to_string(out.points) + " of its observations are of calibrated points (need " +
                 std::to_string(options.min_points) + ")";
    return out;
  }
  Fit stored;
  const Eigen::Vector3d stored_centre = Centre(input.R, input.t);
  std::copy(stored_centre.data(), stored_centre.data() + 3, stored.c);

  // With a distortion, the fits compare distorted pixels (see HeldPointResidual).
  const Lens lens = LensOf(input.dist);
  const Eigen::Matrix2Xd observed = lens.distorted ? Distorted(input.K, input.dist, input.observed) : input.observed;
  const Eigen::Matrix2Xd reference_observed =
      lens.distorted ? Distorted(input.K, input.dist, input.reference_observed) : input.reference_observed;
  const Observations now{input.K, lens, input.R, input.points, observed};
  std::vector<int> used;
  const Fit both = RobustFit(now, stored, options, &used);
  out.inliers = static_cast<int>(used.size());
  if (out.inliers < options.min_points) {
    out.reason = "only " + std::to_string(out.inliers) + " of its " + std::to_string(out.points) +
                 " observations agree with one camera (need " + std::to_string(options.min_points) + ")";
    return out;
  }
  if (!both.converged) {
    out.reason = "its fit to the " + std::to_string(out.inliers) + " observations did not converge";
    return out;
  }
  const Fit pose = Solve(now, used, Freed::kPose, stored, options);
  const Fit focal = Solve(now, used, Freed::kFocal, stored, options);
  const int n = out.inliers;
  out.noise_px = NoiseOf(both, n);
  // What two recordings of an unchanged camera differ by beyond the noise of one.
  const double model_variance = options.model_error_px * options.model_error_px;
  const double variance = out.noise_px * out.noise_px + model_variance;
  out.rms_before_px = std::sqrt(SumSquares(now, stored, used) / n);

  // The change (w, centre, focal scale) against its covariance. Its reference is the
  // same fit to the observations the calibration was made from, when given: the stored
  // camera fits its own points far better than its sigma (relative to the other
  // cameras) says, and it is against those points that the new observations are
  // tested. Otherwise the stored camera, with its sigmas.
  Fit reference = stored;
  Eigen::Matrix<double, 7, 7> reference_covariance = Eigen::Matrix<double, 7, 7>::Zero();
  const Observations then{input.K, lens, input.R, input.reference_points, reference_observed};
  std::vector<int> reference_used;
  bool measured_reference = false;
  double reference_variance = 0.0;  // of one coordinate, with measured_reference
  const Fit earlier = then.size() >= options.min_points ? RobustFit(then, stored, options, &reference_used) : stored;
  if (then.size() >= options.min_points && earlier.converged &&
      static_cast<int>(reference_used.size()) >= options.min_points) {
    reference = earlier;
    const double noise = NoiseOf(earlier, static_cast<int>(reference_used.size()));
    reference_variance = noise * noise + model_variance;
    reference_covariance = Inverse(earlier.information) * reference_variance;
    measured_reference = true;
    out.reference = "its calibration's observations";
  } else {
    for (int k = 0; k < 3; ++k) {
      reference_covariance(k, k) = input.rotation_sigma * input.rotation_sigma;
      reference_covariance(3 + k, 3 + k) = input.centre_sigma * input.centre_sigma;
    }
    out.reference = "the stored pose's sigmas";
  }
  Eigen::Matrix<double, 7, 1> change;
  change << both.w[0] - reference.w[0], both.w[1] - reference.w[1], both.w[2] - reference.w[2],
      both.c[0] - reference.c[0], both.c[1] - reference.c[1], both.c[2] - reference.c[2], both.s - reference.s;
  const Eigen::Matrix<double, 7, 7> covariance = Inverse(both.information) * variance + reference_covariance;
  // The reference's variance of the parameters a fit frees (the stored sigmas' as they are).
  const auto reference_covariance_of = [&](Freed freed) -> Eigen::Matrix<double, 7, 7> {
    if (!measured_reference) return reference_covariance;
    return CovarianceOf(earlier.information, freed) * reference_variance;
  };
  out.chi2 = change.dot(covariance.completeOrthogonalDecomposition().solve(change));
  out.chi2_threshold = ChiSquareQuantile(7, options.significance_z);

  // The simplest fit that explains the observations as well as both together.
  const double pose_gain = (focal.ssr - both.ssr) / variance;  // what the pose adds to the focal length
  const double focal_gain = (pose.ssr - both.ssr) / variance;  // what the focal length adds to the pose
  const Fit* chosen = &both;
  Freed freed = Freed::kBoth;
  Status changed = Status::kRezoomed;
  std::string kind = "its focal length and pose changed";
  // A focal change too small to move any pixel by the tolerance is no re-zoom, however
  // significant (two recordings differ by more than their noise in small ways).
  const bool focal_visible = std::abs(both.s / reference.s - 1.0) * LargestRadius(input) > options.tolerance_px;
  if (pose_gain <= ChiSquareQuantile(6, options.significance_z)) {
    chosen = &focal;
    freed = Freed::kFocal;
    kind = "its focal length changed (re-zoomed)";
  } else if (focal_gain <= ChiSquareQuantile(1, options.significance_z) || !focal_visible) {
    chosen = &pose;
    freed = Freed::kPose;
    changed = Status::kMoved;
    kind = "it moved";
  }
  // The chosen fit's own reference: the same parameters fitted to the calibration's
  // observations (a weak camera's focal length and depth trade off there too).
  const Fit chosen_reference =
      measured_reference ? Solve(then, reference_used, freed, stored, options) : stored;
  const Pinhole now_camera = PinholeOf(*chosen, input.R);
  out.volume_shift_px = VolumeShift(input, PinholeOf(chosen_reference, input.R), now_camera);

  const bool significant = out.chi2 > out.chi2_threshold;
  const bool visible = out.volume_shift_px > options.tolerance_px;
  // A change is described by the fit that explains it against its reference; no change
  // by the fit of both, whose figures bound what may have changed unseen.
  const Fit& described = significant && visible ? *chosen : both;
  const Fit& from = significant && visible ? chosen_reference : reference;
  const Freed described_freed = significant && visible ? freed : Freed::kBoth;
  out.volume_shift_sigma_px = VolumeShiftSigma(
      input, CovarianceOf(described.information, described_freed) * variance + reference_covariance_of(described_freed));
  const Eigen::Matrix3d turn = RotationOf(described.w, input.R) * RotationOf(from.w, input.R).transpose();
  out.rotation_change_deg = Eigen::AngleAxisd(turn).angle() * kRadToDeg;
  out.centre_change = (Eigen::Vector3d(described.c[0], described.c[1], described.c[2]) -
                       Eigen::Vector3d(from.c[0], from.c[1], from.c[2])).norm();
  out.focal_change = described.s / from.s - 1.0;
  out.rotation_sigma_deg =
      std::sqrt(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(covariance.block<3, 3>(0, 0)).eigenvalues().maxCoeff()) *
      kRadToDeg;
  out.centre_sigma =
      std::sqrt(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(covariance.block<3, 3>(3, 3)).eigenvalues().maxCoeff());
  out.focal_sigma = std::sqrt(std::max(0.0, covariance(6, 6)));

  const std::string figures =
      Figures("rotation %.3g deg, centre %.3g (calibration units), focal %+.2g %%; "
              "the working volume moves up to %.2f +- %.2f px in its image",
              out.rotation_change_deg, out.centre_change, 100.0 * out.focal_change, out.volume_shift_px,
              out.volume_shift_sigma_px) +
      Figures(" (tolerance %.2g px), chi-square %.1f (%.1f is noise at %.4g %%)", options.tolerance_px, out.chi2,
              out.chi2_threshold, 100.0 * (1.0 - 0.5 * std::erfc(options.significance_z / std::sqrt(2.0))));
  if (significant && visible) {
    out.status = changed;
    out.R = now_camera.R;
    out.t = now_camera.t;
    out.focal_scale = chosen->s;
    out.fit_covariance = CovarianceOf(chosen->information, freed) * variance;
    out.rms_after_px = std::sqrt(SumSquares(now, *chosen, used) / n);
    out.reason = kind + ": " + figures;
  } else {
    out.status = Status::kUnchanged;
    out.rms_after_px = out.rms_before_px;
    out.reason = std::string(significant ? "a change within the tolerance: " : "no significant change: ") + figures;
  }
  return out;
}

}  // namespace calibproj::check
