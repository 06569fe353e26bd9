#include "calibproj/registration/noise_model.h"

#include <Eigen/Dense>
#include <utility>
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

NoiseProblem::NoiseProblem(const NoiseInputs& in)
    : num_cameras_(static_cast<int>(in.registered->size())),
      gauge_camera_(in.gauge_camera),
      has_projector_(in.projector != nullptr && in.surfaces != nullptr &&
                     in.projector->rows() == static_cast<Eigen::Index>(in.reconstructed->size())),
      projector_width_(in.projector_width) {
  const int num_points = static_cast<int>(in.reconstructed->size());
  std::vector<std::vector<int>> observations(num_points);
  for (int i = 0; i < in.camera_index->size(); ++i) {
    const int c = (*in.camera_index)(i), p = (*in.point_index)(i);
    if ((*in.active)[i] && (*in.registered)[c] && (*in.reconstructed)[p]) observations[p].push_back(i);
  }
  std::vector<Eigen::Matrix3d> rotations(num_cameras_);
  for (int c = 0; c < num_cameras_; ++c) {
    rotations[c] = ba::RotationFromAngleAxis(in.poses->row(c).head<3>().transpose());
  }
  if (has_projector_) {
    for (const auto& surface : *in.surfaces) projector_maps_ += surface.valid ? 1 : 0;
    projector_groups_ = static_cast<int>(in.projector_sigma_px.size());
  }
  for (int p = 0; p < num_points; ++p) {
    if (observations[p].empty()) continue;
    const Eigen::Vector3d X = in.points->row(p).transpose();
    const int k = (*in.point_plane)[p];
    // The point's directions of freedom: its plane's, or all three when free.
    Eigen::MatrixXd D = Eigen::Matrix3d::Identity();
    if (k >= 0) D = PlaneDirections((*in.planes)[k]);
    Point point;
    point.dof = static_cast<int>(D.cols());
    for (int i : observations[p]) {
      const int c = (*in.camera_index)(i);
      Eigen::Vector2d pixel;
      Eigen::Matrix<double, 2, 3> J;
      if (!ProjectWorld((*in.intrinsics)[c], rotations[c], in.poses->row(c).tail<3>().transpose(), X, &pixel, &J)) {
        continue;
      }
      point.observations.push_back({c, J * D, pixel - in.observed->row(i).transpose()});
    }
    Eigen::Matrix2d J_proj;
    const int group = in.projector_group ? (*in.projector_group)[p] : 0;
    if (has_projector_ && k >= 0 && k < static_cast<int>(in.surfaces->size()) && (*in.surfaces)[k].valid &&
        in.projector->row(p).allFinite() && group >= 0 && group < projector_groups_) {
      const ba::ProjectorSurface& surface = (*in.surfaces)[k];
      Eigen::Vector3d predicted;
      if (ba::ProjectorPoint(surface, in.lens, in.projector->row(p).transpose(), &predicted) &&
          ProjectorJacobian(surface, X, D, &J_proj)) {
        point.has_projector = true;
        point.projector_group = group;
        point.J_projector = J_proj;
        point.projector_error = J_proj * D.transpose() * (X - predicted);  // first order
      }
    }
    if (!point.observations.empty()) points_.push_back(std::move(point));
  }
}

NoiseEstimate NoiseProblem::Estimate(const std::vector<double>& camera_sigma_px,
                                     const std::vector<double>& projector_sigma_px) const {
  using Square = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 3, 3>;
  using Vector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 3, 1>;
  std::vector<double> camera_sum(num_cameras_, 0.0), camera_r(num_cameras_, 0.0);
  std::vector<double> projector_sum(projector_groups_, 0.0), projector_r(projector_groups_, 0.0);
  std::vector<double> projector_var(projector_groups_, 0.0);
  for (int g = 0; g < projector_groups_; ++g) {
    projector_var[g] = projector_sigma_px[g] * projector_sigma_px[g] / (projector_width_ * projector_width_);
  }
  for (const Point& point : points_) {
    Square N = Square::Zero(point.dof, point.dof);
    Vector gradient = Vector::Zero(point.dof);
    for (const Observation& o : point.observations) {
      const double var = camera_sigma_px[o.camera] * camera_sigma_px[o.camera];
      N.noalias() += o.J.transpose() * o.J / var;
      gradient.noalias() += o.J.transpose() * o.error / var;
    }
    const double p_var = point.has_projector ? projector_var[point.projector_group] : 0.0;
    const bool projector_term = point.has_projector && p_var > 0.0;
    if (projector_term) {
      N.noalias() += point.J_projector.transpose() * point.J_projector / p_var;
      gradient.noalias() += point.J_projector.transpose() * point.projector_error / p_var;
    }
    const Eigen::FullPivLU<Square> lu(N);
    if (lu.rank() < point.dof) continue;
    const Square N_inv = lu.inverse();
    // The point as these weights would place it (one Gauss-Newton step from where the
    // adjustment put it under the weights it had): the estimate can then be iterated to
    // its fixed point without a new adjustment.
    const Vector step = -N_inv * gradient;
    for (const Observation& o : point.observations) {
      const double var = camera_sigma_px[o.camera] * camera_sigma_px[o.camera];
      camera_sum[o.camera] += (o.error + o.J * step).squaredNorm();
      camera_r[o.camera] += 2.0 - (o.J * N_inv * o.J.transpose()).trace() / var;
    }
    // A point one camera alone sees tells only the sum of that camera's and the
    // projector's variances, not how it splits (any split fits its residuals equally):
    // the projector's share is taken where cameras fix the point.
    if (projector_term && point.observations.size() >= 2) {
      const int g = point.projector_group;
      projector_sum[g] += (point.projector_error + point.J_projector * step).squaredNorm() * projector_width_ *
                          projector_width_;
      projector_r[g] += 2.0 - (point.J_projector * N_inv * point.J_projector.transpose()).trace() / p_var;
    }
  }
  NoiseEstimate out;
  out.camera_sigma_px.assign(num_cameras_, std::numeric_limits<double>::quiet_NaN());
  out.camera_redundancy.assign(num_cameras_, 0.0);
  for (int c = 0; c < num_cameras_; ++c) {
    const double r = camera_r[c] - (c == gauge_camera_ ? 0.0 : 6.0);
    out.camera_redundancy[c] = r;
    if (r >= 1.0) out.camera_sigma_px[c] = std::sqrt(camera_sum[c] / r);
  }
  out.projector_sigma_px.assign(projector_groups_, std::numeric_limits<double>::quiet_NaN());
  out.projector_redundancy.assign(projector_groups_, 0.0);
  if (has_projector_ && projector_groups_ > 0) {
    // The maps' and lens's parameters take their redundancy from every group, each in
    // proportion to its own.
    const double spent = 8.0 * projector_maps_ + (projector_maps_ > 0 ? 2.0 : 0.0);
    double total_r = 0.0, total_sum = 0.0;
    for (int g = 0; g < projector_groups_; ++g) {
      total_r += projector_r[g];
      total_sum += projector_sum[g];
    }
    if (total_r > 0.0) {
      for (int g = 0; g < projector_groups_; ++g) {
        const double r = projector_r[g] * (1.0 - spent / total_r);
        out.projector_redundancy[g] = r;
        if (r >= 1.0) out.projector_sigma_px[g] = std::sqrt(projector_sum[g] / r);
      }
      if (total_r - spent >= 1.0) out.pooled_projector_sigma_px = std::sqrt(total_sum / (total_r - spent));
    }
  }
  return out;
}

NoiseEstimate EstimateNoise(const NoiseInputs& in) {
  return NoiseProblem(in).Estimate(in.camera_sigma_px, in.projector_sigma_px);
}

}  // namespace calibproj::registration
