#include "calibproj/geometry/triangulation.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

namespace calibproj::geometry {

Eigen::Vector4d TriangulateHomogeneous(const std::vector<View>& views) {
  Eigen::MatrixXd A(2 * views.size(), 4);
  for (size_t k = 0; k < views.size(); ++k) {
    Eigen::Matrix<double, 3, 4> P;
    P << views[k].R, views[k].t;
    A.row(2 * k) = views[k].ray.x() * P.row(2) - P.row(0);
    A.row(2 * k + 1) = views[k].ray.y() * P.row(2) - P.row(1);
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullV);
  return svd.matrixV().col(3);
}

Eigen::Vector3d TriangulateLinear(const std::vector<View>& views) { return TriangulateHomogeneous(views).hnormalized(); }

double MaxTriangulationAngle(const std::vector<View>& views, const Eigen::Vector3d& X) {
  std::vector<Eigen::Vector3d> directions;
  for (const View& view : views) {
    const Eigen::Vector3d centre = -view.R.transpose() * view.t;
    directions.push_back((X - centre).normalized());
  }
  double best = 0.0;
  for (size_t i = 0; i < directions.size(); ++i) {
    for (size_t j = i + 1; j < directions.size(); ++j) {
      best = std::max(best, std::acos(std::clamp(directions[i].dot(directions[j]), -1.0, 1.0)));
    }
  }
  return best;
}

bool IntersectRayWithPlane(const View& view, const Eigen::Vector4d& plane, Eigen::Vector3d* X) {
  const Eigen::Vector3d centre = -view.R.transpose() * view.t;
  const Eigen::Vector3d direction = view.R.transpose() * view.ray.homogeneous();
  const Eigen::Vector3d n = plane.head<3>();
  const double denominator = n.dot(direction);
  if (std::abs(denominator) < 1e-12) return false;
  const double lambda = (plane(3) - n.dot(centre)) / denominator;
  if (!(lambda > 0.0)) return false;
  *X = centre + lambda * direction;
  return true;
}

}  // namespace calibproj::geometry
