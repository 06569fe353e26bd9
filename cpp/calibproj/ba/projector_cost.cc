#include "calibproj/ba/projector_cost.h"

#include <Eigen/Dense>
#include <cmath>

namespace calibproj::ba {

Eigen::Vector2d UndistortProjector(const Eigen::Vector2d& normalised, const Eigen::Vector2d& lens) {
  const double r2 = normalised.squaredNorm();
  return normalised * (1.0 + lens(0) * r2 + lens(1) * r2 * r2);
}

bool ApplySurfaceMap(const SurfaceMap& g, const Eigen::Vector2d& ab, Eigen::Vector2d* u) {
  const double h3 = g(6) * ab(0) + g(7) * ab(1) + 1.0;
  if (!(std::abs(h3) > 1e-12)) return false;
  *u << (g(0) * ab(0) + g(1) * ab(1) + g(2)) / h3, (g(3) * ab(0) + g(4) * ab(1) + g(5)) / h3;
  return u->allFinite();
}

namespace {

Eigen::Matrix3d AsMatrix(const SurfaceMap& g) {
  Eigen::Matrix3d H;
  H << g(0), g(1), g(2), g(3), g(4), g(5), g(6), g(7), 1.0;
  return H;
}

// Similarity that moves the points' centroid to 0 and their mean distance to sqrt(2).
Eigen::Matrix3d Normaliser(const std::vector<Eigen::Vector2d>& points) {
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& p : points) mean += p;
  mean /= static_cast<double>(points.size());
  double spread = 0.0;
  for (const auto& p : points) spread += (p - mean).norm();
  spread /= static_cast<double>(points.size());
  const double s = spread > 0.0 ? std::sqrt(2.0) / spread : 1.0;
  Eigen::Matrix3d T;
  T << s, 0.0, -s * mean(0), 0.0, s, -s * mean(1), 0.0, 0.0, 1.0;
  return T;
}

}  // namespace

bool InvertSurfaceMap(const SurfaceMap& g, const Eigen::Vector2d& u, Eigen::Vector2d* ab) {
  const Eigen::Vector3d h = AsMatrix(g).inverse() * u.homogeneous();
  if (!h.allFinite() || !(std::abs(h(2)) > 1e-12)) return false;
  *ab = h.head<2>() / h(2);
  return true;
}

bool FitSurfaceMap(const std::vector<Eigen::Vector2d>& ab, const std::vector<Eigen::Vector2d>& u, SurfaceMap* map) {
  if (ab.size() != u.size() || ab.size() < 4) return false;
  const Eigen::Matrix3d Ta = Normaliser(ab), Tu = Normaliser(u);
  Eigen::MatrixXd A(2 * ab.size(), 9);
  for (size_t i = 0; i < ab.size(); ++i) {
    const Eigen::Vector3d x = Ta * ab[i].homogeneous();
    const Eigen::Vector3d y = Tu * u[i].homogeneous();
    A.row(2 * i) << x(0), x(1), 1.0, 0.0, 0.0, 0.0, -y(0) * x(0), -y(0) * x(1), -y(0);
    A.row(2 * i + 1) << 0.0, 0.0, 0.0, x(0), x(1), 1.0, -y(1) * x(0), -y(1) * x(1), -y(1);
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullV);
  const Eigen::VectorXd& s = svd.singularValues();
  if (!(s(7) > 1e-9 * s(0))) return false;  // the points do not fix a homography
  const Eigen::Matrix<double, 9, 1> h = svd.matrixV().col(8);
  Eigen::Matrix3d H;
  H << h(0), h(1), h(2), h(3), h(4), h(5), h(6), h(7), h(8);
  H = Tu.inverse() * H * Ta;
  if (!(std::abs(H(2, 2)) > 1e-12 * H.norm())) return false;
  H /= H(2, 2);
  *map << H(0, 0), H(0, 1), H(0, 2), H(1, 0), H(1, 1), H(1, 2), H(2, 0), H(2, 1);
  return map->allFinite();
}

bool ProjectorSurfaceCost::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  const Eigen::Map<const SurfaceMap> g(parameters[0]);
  const Eigen::Map<const Eigen::Vector2d> lens(parameters[1]);
  const Eigen::Map<const Eigen::Vector2d> ab(parameters[2]);
  const double a = ab(0), b = ab(1);
  const double h1 = g(0) * a + g(1) * b + g(2);
  const double h2 = g(3) * a + g(4) * b + g(5);
  const double h3 = g(6) * a + g(7) * b + 1.0;
  if (!(std::abs(h3) > 1e-12)) return false;
  const double inv = 1.0 / h3;
  const double x = h1 * inv, y = h2 * inv;
  const double r2 = u_.squaredNorm();
  const double radial = 1.0 + lens(0) * r2 + lens(1) * r2 * r2;
  residuals[0] = weight_ * (x - u_(0) * radial);
  residuals[1] = weight_ * (y - u_(1) * radial);
  if (jacobians == nullptr) return true;
  const double w = weight_ * inv;
  if (jacobians[0] != nullptr) {
    Eigen::Map<Eigen::Matrix<double, 2, 8, Eigen::RowMajor>> J(jacobians[0]);
    J << w * a, w * b, w, 0.0, 0.0, 0.0, -w * x * a, -w * x * b,  //
        0.0, 0.0, 0.0, w * a, w * b, w, -w * y * a, -w * y * b;
  }
  if (jacobians[1] != nullptr) {
    Eigen::Map<Eigen::Matrix<double, 2, 2, Eigen::RowMajor>> J(jacobians[1]);
    J << -weight_ * u_(0) * r2, -weight_ * u_(0) * r2 * r2,  //
        -weight_ * u_(1) * r2, -weight_ * u_(1) * r2 * r2;
  }
  if (jacobians[2] != nullptr) {
    Eigen::Map<Eigen::Matrix<double, 2, 2, Eigen::RowMajor>> J(jacobians[2]);
    J << w * (g(0) - x * g(6)), w * (g(1) - x * g(7)),  //
        w * (g(3) - y * g(6)), w * (g(4) - y * g(7));
  }
  return true;
}

}  // namespace calibproj::ba
