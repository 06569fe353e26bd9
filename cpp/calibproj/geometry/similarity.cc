#include "calibproj/geometry/similarity.h"

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <stdexcept>
#include <string>

namespace calibproj::geometry {

Similarity3 EstimateSimilarity(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst) {
  if (src.cols() != dst.cols()) {
    throw std::invalid_argument("similarity: " + std::to_string(src.cols()) + " source points but " +
                                std::to_string(dst.cols()) + " destination points");
  }
  if (src.cols() < 3) {
    throw std::invalid_argument("similarity: needs at least 3 point pairs, got " +
                                std::to_string(src.cols()));
  }
  if (!src.allFinite() || !dst.allFinite()) {
    throw std::invalid_argument("similarity: non-finite coordinates");
  }
  // Collinear or coincident sources leave the rotation about their line undetermined.
  const Eigen::Matrix3Xd centred = src.colwise() - src.rowwise().mean();
  const Eigen::JacobiSVD<Eigen::Matrix3Xd> svd(centred);
  const Eigen::Vector3d sv = svd.singularValues();
  if (sv(1) <= 1e-9 * std::max(sv(0), 1e-300)) {
    throw std::invalid_argument("similarity: source points are collinear or coincident");
  }
  const Eigen::Matrix4d T = Eigen::umeyama(src, dst, /*with_scaling=*/true);
  Similarity3 sim;
  const Eigen::Matrix3d sR = T.topLeftCorner<3, 3>();
  sim.scale = std::cbrt(sR.determinant());
  sim.R = sR / sim.scale;
  sim.t = T.topRightCorner<3, 1>();
  return sim;
}

}  // namespace calibproj::geometry
