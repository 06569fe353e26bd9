#include "calibproj/registration/result.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <limits>
#include <utility>

#include "calibproj/ba/rotation.h"

namespace calibproj::registration {

namespace {

void FillMetrics(const Reconstruction& rec, std::vector<CameraResult>* cameras) {
  const auto residuals = rec.Residuals();
  const Eigen::VectorXi& camera_index = rec.camera_index();
  const Eigen::VectorXi& point_index = rec.point_index();
  std::vector<int> seen_by(rec.num_points(), 0);
  for (int i = 0; i < residuals.rows(); ++i) {
    if (std::isfinite(residuals(i, 0))) ++seen_by[point_index(i)];
  }
  std::vector<double> sum(rec.num_cameras(), 0.0), sum_sq(rec.num_cameras(), 0.0);
  for (int i = 0; i < residuals.rows(); ++i) {
    CameraResult& camera = (*cameras)[camera_index(i)];
    ++camera.observations;
    if (!std::isfinite(residuals(i, 0))) continue;
    const double error = residuals.row(i).norm();
    ++camera.inliers;
    if (seen_by[point_index(i)] >= 2) ++camera.track2_observations;
    sum[camera_index(i)] += error;
    sum_sq[camera_index(i)] += error * error;
  }
  for (int c = 0; c < rec.num_cameras(); ++c) {
    CameraResult& camera = (*cameras)[c];
    camera.view_score = rec.ViewScore(c);
    if (camera.registered && camera.inliers > 0) {
      camera.mean_px = sum[c] / camera.inliers;
      camera.std_px = std::sqrt(std::max(0.0, sum_sq[c] / camera.inliers - camera.mean_px * camera.mean_px));
    }
  }
}

// Largest standard deviation of the rotation (degrees) and of the centre (reconstruction
// units) of a camera from the covariance of its [dtheta, dt].
std::pair<double, double> PoseSigmas(const ba::Matrix6d& covariance, const Eigen::Matrix3d& R,
                                     const Eigen::Vector3d& t) {
  const Eigen::Matrix<double, 6, 6> C = covariance;
  if (!C.allFinite()) return {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::quiet_NaN()};
  const Eigen::Matrix3d rotation = C.topLeftCorner<3, 3>();
  // Centre C = -R^T t: dC = -R^T [t]x^T ... = -R^T (dt - [t]x dtheta) to first order.
  Eigen::Matrix<double, 3, 6> J;
  J.leftCols<3>() = -R.transpose() * ba::Skew(t);
  J.rightCols<3>() = -R.transpose();
  const Eigen::Matrix3d centre = J * C * J.transpose();
  const auto largest = [](const Eigen::Matrix3d& m) {
    return std::sqrt(std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(m).eigenvalues().maxCoeff()));
  };
  return {largest(rotation) * 180.0 / M_PI, largest(centre)};
}

// The joint pose covariance of the registered cameras in the floor frame X_f = s M (X - o):
// a camera's R_f = R M^T keeps dtheta, and t_f = s (R o + t) moves by s (dt - [R o]x dtheta).
// Refined lenses follow the poses, unchanged by the frame.
PoseUncertainty FloorFrameUncertainty(const Reconstruction& rec, const std::vector<int>& registered,
                                      const ba::PoseMatrix& poses, const FloorFrame& frame) {
  PoseUncertainty out;
  const Eigen::MatrixXd& poses_joint = rec.pose_covariance();
  const int C = rec.num_cameras();
  if (poses_joint.rows() != 6 * C) return out;
  constexpr int L = PoseUncertainty::kLensSize;
  const bool lenses = rec.lens_covariance().rows() == L * C;
  // Every camera's pose, then every camera's lens, as the reconstruction holds them.
  Eigen::MatrixXd joint = poses_joint;
  if (lenses) {
    joint.resize((6 + L) * C, (6 + L) * C);
    joint << poses_joint, rec.pose_lens_covariance(), rec.pose_lens_covariance().transpose(), rec.lens_covariance();
  }
  const int n = static_cast<int>(registered.size());
  std::vector<int> rows;
  for (int k = 0; k < n; ++k) {
    for (int i = 0; i < 6; ++i) rows.push_back(6 * registered[k] + i);
  }
  for (int k = 0; k < n && lenses; ++k) {
    const int c = registered[k];
    out.lens_block.push_back(rec.has_lens(c) ? out.num_lenses() : -1);
    for (int i = 0; i < L && rec.has_lens(c); ++i) rows.push_back(6 * C + L * c + i);
  }
  Eigen::MatrixXd B = Eigen::MatrixXd::Identity(static_cast<Eigen::Index>(rows.size()), static_cast<Eigen::Index>(rows.size()));
  for (int k = 0; k < n; ++k) {
    const Eigen::Matrix3d R = ba::RotationFromAngleAxis(poses.row(k).head<3>().transpose());
    B.block<3, 3>(6 * k + 3, 6 * k) = -frame.scale * ba::Skew(R * frame.origin);
    B.block<3, 3>(6 * k + 3, 6 * k + 3) = frame.scale * Eigen::Matrix3d::Identity();
  }
  const Eigen::MatrixXd sub = joint(rows, rows);
  if (!sub.allFinite()) return PoseUncertainty();
  out.covariance = B * sub * B.transpose();
  out.covariance = 0.5 * (out.covariance + out.covariance.transpose());
  if (out.num_lenses() == 0) out.lens_block.clear();
  for (int k = 0; k < n; ++k) {
    out.cameras.push_back(std::to_string(registered[k]));
    out.noise_px.push_back(rec.covariance_noise_px()[registered[k]]);
  }
  out.reference = std::to_string(rec.gauge_camera());
  return out;
}

}  // namespace

RegistrationResult Summarize(const Reconstruction& rec) {
  RegistrationResult result;
  result.cameras.resize(rec.num_cameras());
  result.registration_order = rec.registration_order();
  std::vector<int> registered;
  for (int c = 0; c < rec.num_cameras(); ++c) {
    result.cameras[c].registered = rec.registered(c);
    result.cameras[c].failure = rec.failure_reasons()[c];
    if (rec.registered(c)) registered.push_back(c);
  }
  FillMetrics(rec, &result.cameras);
  const bool coplanar = rec.options().model == ba::Model::kCoplanar;
  for (int p = 0; p < rec.num_points(); ++p) {
    if (!rec.reconstructed()[p]) continue;
    result.point_index.push_back(p);
    result.point_plane.push_back(coplanar ? rec.point_plane()[p] : -1);
  }
  if (registered.empty()) return result;

  ba::PoseMatrix poses(registered.size(), 6);
  for (size_t k = 0; k < registered.size(); ++k) poses.row(k) = rec.poses().row(registered[k]);
  result.points.resize(result.point_index.size(), 3);
  for (size_t k = 0; k < result.point_index.size(); ++k) result.points.row(k) = rec.points().row(result.point_index[k]);
  const Eigen::Vector4d plane = rec.options().model == ba::Model::kCoplanar ? rec.plane() : FitPlaneRobust(result.points);
  int first = 0;
  for (int c : result.registration_order) {
    const auto it = std::find(registered.begin(), registered.end(), c);
    if (it != registered.end()) {
      first = static_cast<int>(it - registered.begin());
      break;
    }
  }
  result.frame = ComputeFloorFrame(poses, first, plane);
  for (size_t k = 0; k < registered.size(); ++k) {
    CameraResult& camera = result.cameras[registered[k]];
    const Eigen::Matrix3d R = ba::RotationFromAngleAxis(poses.row(k).head<3>().transpose());
    const Eigen::Vector3d t = poses.row(k).tail<3>().transpose();
    camera.R = R * result.frame.M.transpose();
    camera.t = result.frame.scale * (R * result.frame.origin + t);
    if (!rec.pose_covariances().empty()) {
      const auto [rotation_sigma, centre_sigma] = PoseSigmas(rec.pose_covariances()[registered[k]], R, t);
      // A mirror pose the images do not rule out bounds what the covariance can say.
      const int index = registered[k];
      const double ambiguity = index < static_cast<int>(rec.ambiguity_deg().size()) ? rec.ambiguity_deg()[index] : 0.0;
      camera.rotation_sigma_deg = std::max(rotation_sigma, ambiguity);
      camera.centre_sigma = result.frame.scale * centre_sigma;
      camera.weak = camera.rotation_sigma_deg > rec.options().weak_rotation_sigma_deg;
    }
  }
  result.uncertainty = FloorFrameUncertainty(rec, registered, poses, result.frame);
  double sum_sq = 0.0;
  int on_floor = 0;
  for (int p = 0; p < result.points.rows(); ++p) {
    result.points.row(p) =
        (result.frame.scale * result.frame.M * (result.points.row(p).transpose() - result.frame.origin)).transpose();
    if (coplanar && result.point_plane[p] != 0) continue;
    sum_sq += result.points(p, 2) * result.points(p, 2);
    ++on_floor;
  }
  if (on_floor > 0) result.floor_rms = std::sqrt(sum_sq / on_floor);
  // The other planes in the floor frame: n . X = d becomes (M n) . X_f = s (d - n . o).
  result.planes.resize(static_cast<int>(rec.more_planes().size()), 4);
  for (size_t k = 0; k < rec.more_planes().size(); ++k) {
    const Eigen::Vector4d& plane = rec.more_planes()[k];
    const double norm = plane.head<3>().norm();
    Eigen::Vector4d floor_plane;
    floor_plane << result.frame.M * plane.head<3>() / norm,
        result.frame.scale * (plane(3) - plane.head<3>().dot(result.frame.origin)) / norm;
    if (floor_plane(2) < 0.0) floor_plane = -floor_plane;
    result.planes.row(static_cast<int>(k)) = floor_plane.transpose();
  }
  return result;
}

}  // namespace calibproj::registration
