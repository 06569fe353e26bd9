#include "calibproj/registration/noise_model.h"

#include <Eigen/Dense>
#include <cmath>
#include <limits>

#include "calibproj/ba/rotation.h"

namespace calibproj::registration {

namespace {

// Columns: two orthonormal directions of the plane [n, d].
Eigen::Matrix<double, 3, 2> PlaneDirections(const Eigen::Vector4d& plane) {
  const Eigen::Vector3d n = plane.head<3>().normalized();
  const Eigen::Vector3d u = n.unitOrthogonal();
  Eigen::Matrix<double, 3, 2> B;
  B << u, n.cross(u);
  return B;
}

// Pixel of the world point X in a camera and its derivative by X.
bool ProjectWorld(const ba::Intrinsics& K, const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                  const Eigen::Vector3d& X, Eigen::Vector2d* pixel, Eigen::Matrix<double, 2, 3>* J) {
  Eigen::Matrix<double, 2, 3> J_cam;
  if (!ba::ProjectPoint(K, R * X + t, pixel, &J_cam)) return false;
  *J = J_cam * R;
  return true;
}

// d(undistorted normalised projector coordinate)/d(world point) along the surface's
// plane directions D (3 x 2), at the world point X: G maps plane coordinates (a, b)
// with X = M [a, b, 1] to u.
bool ProjectorJacobian(const ba::ProjectorSurface& surface, const Eigen::Vector3d& X,
                       const Eigen::Matrix<double, 3, 2>& D, Eigen::Matrix2d* J) {
  const Eigen::Matrix<double, 3, 2> M2 = surface.world_from_plane.leftCols<2>();
  const Eigen::Matrix2d pinv_gram = (M2.transpose() * M2).inverse();
  const Eigen::Vector2d ab = pinv_gram * M2.transpose() * (X - surface.world_from_plane.col(2));
  const ba::SurfaceMap& g = surface.map;
  const double h1 = g(0) * ab(0) + g(1) * ab(1) + g(2), h2 = g(3) * ab(0) + g(4) * ab(1) + g(5);
  const double h3 = g(6) * ab(0) + g(7) * ab(1) + 1.0;
  if (!(std::abs(h3) > 1e-12)) return false;
  const double x = h1 / h3, y = h2 / h3;
  Eigen::Matrix2d dG;
  dG << (g(0) - x * g(6)) / h3, (g(1) - x * g(7)) / h3, (g(3) - y * g(6)) / h3, (g(4) - y * g(7)) / h3;
  // (a, b) of a point moved along D: d(ab) = pinv(M2) D.
  *J = dG * pinv_gram * M2.transpose() * D;
  return J->allFinite();
}

}  // namespace

NoiseEstimate EstimateNoise(const NoiseInputs& in) {
  const int num_cameras = static_cast<int>(in.registered->size());
  const int num_points = static_cast<int>(in.reconstructed->size());
  std::vector<std::vector<int>> observations(num_points);
  for (int i = 0; i < in.camera_index->size(); ++i) {
    const int c = (*in.camera_index)(i), p = (*in.point_index)(i);
    if ((*in.active)[i] && (*in.registered)[c] && (*in.reconstructed)[p]) observations[p].push_back(i);
  }
  std::vector<Eigen::Matrix3d> rotations(num_cameras);
  for (int c = 0; c < num_cameras; ++c) {
    rotations[c] = ba::RotationFromAngleAxis(in.poses->row(c).head<3>().transpose());
  }
  std::vector<double> camera_sum(num_cameras, 0.0), camera_r(num_cameras, 0.0);
  double projector_sum = 0.0, projector_r = 0.0;
  const bool has_projector = in.projector != nullptr && in.projector->rows() == num_points && in.surfaces != nullptr;
  const double projector_var = in.projector_sigma_px * in.projector_sigma_px /
                               (in.projector_width * in.projector_width);  // normalised units
  for (int p = 0; p < num_points; ++p) {
    if (observations[p].empty()) continue;
    const Eigen::Vector3d X = in.points->row(p).transpose();
    const int k = (*in.point_plane)[p];
    // The point's directions of freedom: its plane's, or all three when free.
    Eigen::MatrixXd D = Eigen::Matrix3d::Identity();
    if (k >= 0) D = PlaneDirections((*in.planes)[k]);
    const int dof = static_cast<int>(D.cols());
    Eigen::MatrixXd N = Eigen::MatrixXd::Zero(dof, dof);
    std::vector<int> used_obs;
    std::vector<Eigen::MatrixXd> J_obs;
    std::vector<double> var_obs, error_obs;
    for (int i : observations[p]) {
      const int c = (*in.camera_index)(i);
      Eigen::Vector2d pixel;
      Eigen::Matrix<double, 2, 3> J;
      if (!ProjectWorld((*in.intrinsics)[c], rotations[c], in.poses->row(c).tail<3>().transpose(), X, &pixel, &J)) {
        continue;
      }
      const double var = in.camera_sigma_px[c] * in.camera_sigma_px[c];
      used_obs.push_back(i);
      J_obs.push_back(J * D);
      var_obs.push_back(var);
      error_obs.push_back((pixel - in.observed->row(i).transpose()).squaredNorm());
      N += J_obs.back().transpose() * J_obs.back() / var;
    }
    Eigen::Matrix2d J_proj;
    Eigen::Vector2d e_proj;
    bool projector_term = false;
    if (has_projector && k >= 0 && k < static_cast<int>(in.surfaces->size()) && (*in.surfaces)[k].valid &&
        in.projector->row(p).allFinite() && projector_var > 0.0) {
      const ba::ProjectorSurface& surface = (*in.surfaces)[k];
      Eigen::Vector3d predicted;
      if (ba::ProjectorPoint(surface, in.lens, in.projector->row(p).transpose(), &predicted) &&
          ProjectorJacobian(surface, X, D, &J_proj)) {
        e_proj = J_proj * D.transpose() * (X - predicted);  // first order, normalised units
        N += J_proj.transpose() * J_proj / projector_var;
        projector_term = true;
      }
    }
    const Eigen::FullPivLU<Eigen::MatrixXd> lu(N);
    if (lu.rank() < dof) continue;
    const Eigen::MatrixXd N_inv = lu.inverse();
    for (size_t k_obs = 0; k_obs < used_obs.size(); ++k_obs) {
      const int c = (*in.camera_index)(used_obs[k_obs]);
      const Eigen::MatrixXd& J = J_obs[k_obs];
      camera_sum[c] += error_obs[k_obs];
      camera_r[c] += 2.0 - (J * N_inv * J.transpose()).trace() / var_obs[k_obs];
    }
    if (projector_term) {
      projector_sum += e_proj.squaredNorm() * in.projector_width * in.projector_width;
      projector_r += 2.0 - (J_proj * N_inv * J_proj.transpose()).trace() / projector_var;
    }
  }
  NoiseEstimate out;
  out.camera_sigma_px.assign(num_cameras, std::numeric_limits<double>::quiet_NaN());
  out.camera_redundancy.assign(num_cameras, 0.0);
  for (int c = 0; c < num_cameras; ++c) {
    const double r = camera_r[c] - (c == in.gauge_camera ? 0.0 : 6.0);
    out.camera_redundancy[c] = r;
    if (r >= 1.0) out.camera_sigma_px[c] = std::sqrt(camera_sum[c] / r);
  }
  if (has_projector && in.surfaces != nullptr) {
    int maps = 0;
    for (const auto& surface : *in.surfaces) maps += surface.valid ? 1 : 0;
    out.projector_redundancy = projector_r - 8.0 * maps - (maps > 0 ? 2.0 : 0.0);
    if (out.projector_redundancy >= 1.0) out.projector_sigma_px = std::sqrt(projector_sum / out.projector_redundancy);
  }
  return out;
}

}  // namespace calibproj::registration
