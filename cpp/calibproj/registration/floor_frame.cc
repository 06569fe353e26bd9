#include "calibproj/registration/floor_frame.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "calibproj/ba/rotation.h"

namespace calibproj::registration {

namespace {

double Median(std::vector<double> values) {
  const auto middle = values.begin() + static_cast<long>(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return *middle;
}

}  // namespace

Eigen::Vector4d FitPlaneRobust(const ba::PointMatrix& points, int rounds, double k) {
  const int n_points = static_cast<int>(points.rows());
  if (n_points < 3) throw std::invalid_argument("cannot fit the floor plane to " + std::to_string(n_points) + " points");
  std::vector<bool> inlier(n_points, true);
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ(), centroid = Eigen::Vector3d::Zero();
  for (int round = 0; round < rounds; ++round) {
    centroid.setZero();
    int count = 0;
    for (int i = 0; i < n_points; ++i) {
      if (inlier[i]) {
        centroid += points.row(i).transpose();
        ++count;
      }
    }
    centroid /= count;
    Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
    for (int i = 0; i < n_points; ++i) {
      if (!inlier[i]) continue;
      const Eigen::Vector3d d = points.row(i).transpose() - centroid;
      scatter += d * d.transpose();
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(scatter);
    normal = eigen.eigenvectors().col(0);
    std::vector<double> distances(n_points), inlier_distances;
    for (int i = 0; i < n_points; ++i) {
      distances[i] = std::abs((points.row(i).transpose() - centroid).dot(normal));
      if (inlier[i]) inlier_distances.push_back(distances[i]);
    }
    const double threshold = std::max(k * 1.4826 * Median(inlier_distances), 1e-12);
    std::vector<bool> keep(n_points);
    int kept = 0;
    for (int i = 0; i < n_points; ++i) kept += (keep[i] = distances[i] <= threshold);
    if (kept < 3 || keep == inlier) break;
    inlier = keep;
  }
  Eigen::Vector4d plane;
  plane << normal, normal.dot(centroid);
  return plane;
}

FloorFrame ComputeFloorFrame(const ba::PoseMatrix& poses, int first, const Eigen::Vector4d& plane) {
  const int num = static_cast<int>(poses.rows());
  if (first < 0 || first >= num) throw std::invalid_argument("floor frame: first camera out of range");
  Eigen::Vector3d n = plane.head<3>();
  double d = plane(3) / n.norm();
  n.normalize();
  std::vector<Eigen::Matrix3d> rotations(num);
  std::vector<Eigen::Vector3d> centres(num);
  double mean_height = 0.0;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (int c = 0; c < num; ++c) {
    rotations[c] = ba::RotationFromAngleAxis(poses.row(c).head<3>().transpose());
    centres[c] = -rotations[c].transpose() * poses.row(c).tail<3>().transpose();
    mean_height += n.dot(centres[c]) - d;
    centroid += centres[c];
  }
  centroid /= num;
  if (mean_height < 0.0) {  // z points towards the cameras
    n = -n;
    d = -d;
  }
  const double first_height = n.dot(centres[first]) - d;
  if (!(first_height > 0.0)) throw std::runtime_error("floor frame: the first camera is not above the floor plane");
  FloorFrame frame;
  frame.origin = centroid - (n.dot(centroid) - d) * n;
  Eigen::Vector3d axis = rotations[first].transpose() * Eigen::Vector3d::UnitZ();
  Eigen::Vector3d x_axis = axis - axis.dot(n) * n;
  if (x_axis.norm() < 1e-6) {  // looking straight down: use the image x axis
    axis = rotations[first].transpose() * Eigen::Vector3d::UnitX();
    x_axis = axis - axis.dot(n) * n;
  }
  x_axis.normalize();
  frame.M.row(0) = x_axis.transpose();
  frame.M.row(1) = n.cross(x_axis).transpose();
  frame.M.row(2) = n.transpose();
  frame.scale = 1.0 / first_height;
  return frame;
}

}  // namespace calibproj::registration
