#include "calibproj/selfcal/self_calibration.h"

#include <ceres/ceres.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>

#include "calibproj/common/limits.h"
#include "calibproj/selfcal/planar_cost.h"

namespace calibproj::selfcal {

namespace {

std::string Str(int v) { return std::to_string(v); }

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument(message);
}

// Smallest eigenvalue kept, relative to the largest, when the reduced information
// matrix is inverted: directions below it are not determined by the data.
constexpr double kRelativeEigenvalueFloor = 1e-12;

// The most observed point, and the point farthest from it among those observed at
// least half as often (they fix the floor's similarity gauge).
Eigen::Vector2i GaugePoints(const Data& data) {
  std::vector<int> count(data.points.rows(), 0);
  for (int i = 0; i < data.point_index.size(); ++i) ++count[data.point_index(i)];
  const int first = static_cast<int>(std::max_element(count.begin(), count.end()) - count.begin());
  int second = -1;
  double best = -1.0;
  for (int pass = 0; pass < 2 && second < 0; ++pass) {
    const int needed = pass == 0 ? std::max(2, count[first] / 2) : 1;
    for (int p = 0; p < static_cast<int>(count.size()); ++p) {
      const double distance = (data.points.row(p) - data.points.row(first)).norm();
      if (p != first && count[p] >= needed && distance > best) {
        best = distance;
        second = p;
      }
    }
  }
  return {first, second};
}

ba::PixelMatrix Residuals(const Data& data, const LensMatrix& lenses, const ba::PoseMatrix& poses,
                          const FloorMatrix& points) {
  ba::PixelMatrix out(data.camera_index.size(), 2);
  for (int i = 0; i < data.camera_index.size(); ++i) {
    const int c = data.camera_index(i);
    const PlanarLensCost cost(data.shapes[c], data.observed.row(i).transpose());
    const double* blocks[3] = {poses.row(c).data(), points.row(data.point_index(i)).data(), lenses.row(c).data()};
    double r[2];
    if (cost.Evaluate(blocks, r, nullptr)) {
      out.row(i) << r[0], r[1];
    } else {
      out.row(i).setConstant(std::numeric_limits<double>::quiet_NaN());
    }
  }
  return out;
}

Eigen::VectorXd NoisePerCamera(const Data& data, const ba::PixelMatrix& residuals) {
  const int num_cameras = static_cast<int>(data.poses.rows());
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(num_cameras), count = Eigen::VectorXd::Zero(num_cameras);
  for (int i = 0; i < residuals.rows(); ++i) {
    if (!residuals.row(i).allFinite()) continue;
    sum(data.camera_index(i)) += residuals.row(i).squaredNorm();
    count(data.camera_index(i)) += 2.0;
  }
  Eigen::VectorXd out(num_cameras);
  for (int c = 0; c < num_cameras; ++c) out(c) = count(c) > 0 ? std::sqrt(sum(c) / count(c)) : 0.0;
  return out;
}

// Column of each camera's pose and refined lens entries in the reduced system.
struct Columns {
  std::vector<int> pose;                     // per camera, first of 6
  std::vector<std::vector<int>> lens;        // per camera, per refined entry
  int size = 0;
};

Columns CameraColumns(const Data& data) {
  Columns columns;
  for (int c = 0; c < static_cast<int>(data.poses.rows()); ++c) {
    columns.pose.push_back(columns.size);
    columns.size += 6;
    std::vector<int> lens;
    for (size_t k = 0; k < data.refine[c].size(); ++k) lens.push_back(columns.size++);
    columns.lens.push_back(lens);
  }
  return columns;
}

// Joint covariance of the lenses at the solution (see the header).
Eigen::MatrixXd LensCovariances(const Data& data, const Result& result) {
  const Columns columns = CameraColumns(data);
  const int n = columns.size;
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(n, n);
  // Observations grouped by point: each point's 2x2 block is eliminated.
  std::vector<std::vector<int>> by_point(data.points.rows());
  for (int i = 0; i < data.point_index.size(); ++i) by_point[data.point_index(i)].push_back(i);
  for (int p = 0; p < static_cast<int>(by_point.size()); ++p) {
    const bool gauge = p == result.gauge_points(0) || p == result.gauge_points(1);
    Eigen::MatrixXd B = Eigen::MatrixXd::Zero(2 * by_point[p].size(), n);  // camera columns
    Eigen::MatrixXd A(2 * by_point[p].size(), 2);                          // point columns
    int row = 0;
    for (const int i : by_point[p]) {
      const int c = data.camera_index(i);
      const PlanarLensCost cost(data.shapes[c], data.observed.row(i).transpose());
      const double* blocks[3] = {result.poses.row(c).data(), result.points.row(p).data(), result.lenses.row(c).data()};
      Eigen::Matrix<double, 2, 6, Eigen::RowMajor> J_pose;
      Eigen::Matrix<double, 2, 2, Eigen::RowMajor> J_floor;
      LensJacobian J_lens;
      double* jacobians[3] = {J_pose.data(), J_floor.data(), J_lens.data()};
      double r[2];
      const double noise = result.noise_px(c);
      if (!cost.Evaluate(blocks, r, jacobians) || !(noise > 0.0)) {
        A.middleRows(row, 2).setZero();
      } else {
        B.block(row, columns.pose[c], 2, 6) = J_pose / noise;
        for (size_t k = 0; k < data.refine[c].size(); ++k) {
          B.block(row, columns.lens[c][k], 2, 1) = J_lens.col(data.refine[c][k]) / noise;
        }
        A.middleRows(row, 2) = J_floor / noise;
      }
      row += 2;
    }
    S.noalias() += B.transpose() * B;
    if (gauge) continue;  // held constant: nothing to eliminate
    const Eigen::Matrix2d H_pp = A.transpose() * A;
    if (std::abs(H_pp.determinant()) <= 1e-300) continue;
    const Eigen::MatrixXd H_pc = A.transpose() * B;
    S.noalias() -= H_pc.transpose() * H_pp.inverse() * H_pc;
  }
  // Jacobi scaling, then an eigen-decomposition whose smallest eigenvalues are floored.
  Eigen::VectorXd scale = S.diagonal().cwiseMax(0.0).cwiseSqrt();
  for (int j = 0; j < n; ++j) scale(j) = scale(j) > 0.0 ? 1.0 / scale(j) : 1.0;
  const Eigen::MatrixXd normalised = scale.asDiagonal() * S * scale.asDiagonal();
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(normalised);
  const double floor = kRelativeEigenvalueFloor * std::max(eigen.eigenvalues().maxCoeff(), 1e-300);
  const Eigen::VectorXd inverse_values = eigen.eigenvalues().cwiseMax(floor).cwiseInverse();
  const Eigen::MatrixXd product =
      scale.asDiagonal() * (eigen.eigenvectors() * inverse_values.asDiagonal() * eigen.eigenvectors().transpose()) *
      scale.asDiagonal();
  // Symmetric to the last bit: the product's rounding is not, and its blocks are read both ways.
  const Eigen::MatrixXd covariance = 0.5 * (product + product.transpose());
  const int C = static_cast<int>(data.poses.rows());
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(kLensSize * C, kLensSize * C);
  for (int c = 0; c < C; ++c) {
    for (int d = 0; d < C; ++d) {
      for (size_t a = 0; a < data.refine[c].size(); ++a) {
        for (size_t b = 0; b < data.refine[d].size(); ++b) {
          out(kLensSize * c + data.refine[c][a], kLensSize * d + data.refine[d][b]) =
              covariance(columns.lens[c][a], columns.lens[d][b]);
        }
      }
    }
  }
  return out;
}

}  // namespace

LensCovariance Result::LensCovarianceOf(int a, int b) const {
  const int cameras = static_cast<int>(lens_covariance.rows() / kLensSize);
  if (a < 0 || b < 0 || a >= cameras || b >= cameras) {
    throw std::invalid_argument("lens covariance: camera out of range (the result holds " + std::to_string(cameras) +
                                (cameras == 0 ? "; none was computed)" : ")"));
  }
  return lens_covariance.block<kLensSize, kLensSize>(kLensSize * a, kLensSize * b);
}

void Options::Check() const {
  Require(loss_scale_px > 0.0 && std::isfinite(loss_scale_px), "options: loss scale must be a positive number of pixels");
  limits::RequireInRange(max_iterations, 0, limits::kMaxIterations, "options: max_iterations");
  limits::RequireInRange(num_threads, 1, limits::kMaxThreads, "options: num_threads");
}

void ValidateData(const Data& data, const Options& options) {
  options.Check();
  const int num_obs = static_cast<int>(data.camera_index.size());
  const int num_cameras = static_cast<int>(data.poses.rows());
  const int num_points = static_cast<int>(data.points.rows());
  Require(num_obs > 0 && num_cameras > 0, "empty problem: no observations or no cameras");
  Require(num_points >= 2, "self-calibration needs at least 2 points (they fix the floor's gauge)");
  Require(data.point_index.size() == num_obs && data.observed.rows() == num_obs,
          "observations: camera indices, point indices and pixels differ in number");
  Require(data.lenses.rows() == num_cameras && static_cast<int>(data.shapes.size()) == num_cameras &&
              static_cast<int>(data.refine.size()) == num_cameras,
          "cameras: poses, lenses, lens shapes and refined entries differ in number");
  Require(data.poses.allFinite() && data.points.allFinite() && data.observed.allFinite() && data.lenses.allFinite(),
          "poses, points, pixels and lenses must be finite");
  for (int c = 0; c < num_cameras; ++c) {
    Require(data.lenses(c, kFocal) > 0.0, "lens of camera " + Str(c) + ": the focal length must be positive");
    Require(std::isfinite(data.shapes[c].aspect) && data.shapes[c].aspect > 0.0 &&
                std::isfinite(data.shapes[c].skew_ratio),
            "lens of camera " + Str(c) + ": aspect must be positive and skew finite");
    std::vector<int> entries = data.refine[c];
    std::sort(entries.begin(), entries.end());
    Require(std::adjacent_find(entries.begin(), entries.end()) == entries.end(),
            "camera " + Str(c) + ": a lens entry is listed twice");
    for (const int k : entries) {
      Require(k >= 0 && k < kLensSize, "camera " + Str(c) + ": lens entry " + Str(k) + " out of range [0, 8)");
    }
  }
  std::vector<int> camera_count(num_cameras, 0), point_count(num_points, 0);
  for (int i = 0; i < num_obs; ++i) {
    const int c = data.camera_index(i), p = data.point_index(i);
    if (c < 0 || c >= num_cameras) Require(false, "observation " + Str(i) + ": camera index out of range");
    if (p < 0 || p >= num_points) Require(false, "observation " + Str(i) + ": point index out of range");
    ++camera_count[c];
    ++point_count[p];
  }
  for (int c = 0; c < num_cameras; ++c) Require(camera_count[c] > 0, "camera " + Str(c) + " has no observation");
  for (int p = 0; p < num_points; ++p) Require(point_count[p] > 0, "point " + Str(p) + " has no observation");
  const ba::PixelMatrix residuals = Residuals(data, data.lenses, data.poses, data.points);
  for (int i = 0; i < num_obs; ++i) {
    Require(residuals.row(i).allFinite(), "observation " + Str(i) + ": point " + Str(data.point_index(i)) +
                                              " cannot be projected into camera " + Str(data.camera_index(i)));
  }
}

Result SelfCalibrate(const Data& data, const Options& options) {
  ValidateData(data, options);
  Result result;
  result.lenses = data.lenses;
  result.poses = data.poses;
  result.points = data.points;
  result.gauge_points = GaugePoints(data);
  Require(result.gauge_points(1) >= 0, "self-calibration: no second point to fix the floor's gauge");

  const std::unique_ptr<ceres::LossFunction> loss = ba::MakeLoss(options.loss, options.loss_scale_px);
  ceres::Problem::Options problem_options;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  // Each camera's pose and lens side by side in one buffer: within an elimination group
  // Ceres orders the blocks by address, so two separate allocations would order the
  // reduced camera system by where the heap put them, and the solution's rounding with it.
  constexpr int kCameraBlock = 6 + kLensSize;
  const int num_cameras = static_cast<int>(result.poses.rows());
  std::vector<double> cameras(static_cast<size_t>(num_cameras) * kCameraBlock);
  const auto pose_of = [&](int c) { return cameras.data() + static_cast<size_t>(c) * kCameraBlock; };
  const auto lens_of = [&](int c) { return pose_of(c) + 6; };
  auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
  for (int p = 0; p < result.points.rows(); ++p) {
    problem.AddParameterBlock(result.points.row(p).data(), 2);
    ordering->AddElementToGroup(result.points.row(p).data(), 0);
  }
  for (int c = 0; c < num_cameras; ++c) {
    Eigen::Map<Eigen::Matrix<double, 6, 1>>(pose_of(c)) = result.poses.row(c).transpose();
    Eigen::Map<Eigen::Matrix<double, kLensSize, 1>>(lens_of(c)) = result.lenses.row(c).transpose();
    problem.AddParameterBlock(pose_of(c), 6);
    ordering->AddElementToGroup(pose_of(c), 1);
    std::vector<int> held;
    for (int k = 0; k < kLensSize; ++k) {
      if (std::find(data.refine[c].begin(), data.refine[c].end(), k) == data.refine[c].end()) held.push_back(k);
    }
    problem.AddParameterBlock(lens_of(c), kLensSize);
    ordering->AddElementToGroup(lens_of(c), 1);
    if (held.size() == static_cast<size_t>(kLensSize)) {
      problem.SetParameterBlockConstant(lens_of(c));
    } else if (!held.empty()) {
      problem.SetManifold(lens_of(c), new ceres::SubsetManifold(kLensSize, held));
    }
  }
  for (int i = 0; i < data.camera_index.size(); ++i) {
    const int c = data.camera_index(i);
    problem.AddResidualBlock(new PlanarLensCost(data.shapes[c], data.observed.row(i).transpose()), loss.get(),
                             pose_of(c), result.points.row(data.point_index(i)).data(), lens_of(c));
  }
  for (int g = 0; g < 2; ++g) problem.SetParameterBlockConstant(result.points.row(result.gauge_points(g)).data());

  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::DENSE_SCHUR;
  solver.linear_solver_ordering = ordering;
  solver.max_num_iterations = options.max_iterations;
  solver.function_tolerance = 1e-12;
  solver.gradient_tolerance = 1e-14;
  solver.parameter_tolerance = 1e-12;
  solver.num_threads = options.num_threads;
  solver.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  for (int c = 0; c < num_cameras; ++c) {
    result.poses.row(c) = Eigen::Map<const Eigen::Matrix<double, 6, 1>>(pose_of(c)).transpose();
    result.lenses.row(c) = Eigen::Map<const Eigen::Matrix<double, kLensSize, 1>>(lens_of(c)).transpose();
  }

  result.initial_cost = summary.initial_cost;
  result.final_cost = summary.final_cost;
  result.iterations = static_cast<int>(summary.iterations.size()) - 1;
  result.termination = ceres::TerminationTypeToString(summary.termination_type);
  result.usable = summary.IsSolutionUsable();
  result.residuals = Residuals(data, result.lenses, result.poses, result.points);
  result.noise_px = NoisePerCamera(data, result.residuals);
  if (options.compute_covariance && result.usable) result.lens_covariance = LensCovariances(data, result);
  return result;
}

}  // namespace calibproj::selfcal
