#pragma once
// Points from calibrated views: multi-view triangulation and ray-plane intersection.
// Poses are cam_from_world (x_cam = R X + t); rays are normalised image coordinates.

#include <Eigen/Core>
#include <vector>

namespace calibproj::geometry {

struct View {
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  Eigen::Vector2d ray;  // normalised image coordinates of the observation
};

// Linear (DLT) triangulation from two or more views, in world coordinates.
Eigen::Vector3d TriangulateLinear(const std::vector<View>& views);
// The same in homogeneous coordinates (unit norm): w near 0 for a point at infinity,
// whose rays are parallel.
Eigen::Vector4d TriangulateHomogeneous(const std::vector<View>& views);

// Largest angle (radians) between the viewing rays of X from the views' centres.
double MaxTriangulationAngle(const std::vector<View>& views, const Eigen::Vector3d& X);

// Intersection of the viewing ray of one view with the plane n . X = d; returns false
// if the ray is parallel to the plane or the intersection is behind the camera.
bool IntersectRayWithPlane(const View& view, const Eigen::Vector4d& plane, Eigen::Vector3d* X);

}  // namespace calibproj::geometry
