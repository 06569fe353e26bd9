#pragma once
// Similarity transforms Sim(3): dst ~= scale * R * src + t.

#include <Eigen/Core>

namespace calibproj::geometry {

struct Similarity3 {
  double scale = 1.0;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
};

// Least-squares similarity mapping src points (columns) onto dst points
// (Umeyama 1991, through Eigen::umeyama). Needs at least 3 non-collinear points;
// throws std::invalid_argument otherwise.
Similarity3 EstimateSimilarity(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst);

}  // namespace calibproj::geometry
