#pragma once
// Unit vectors and their tangent planes, shared by the plane manifold (the plane
// normal), the coplanar point parameterisation (in-plane axes) and the scale gauge
// (direction of a translation of fixed length).
//
// The tangent basis of a unit vector n is the first two columns of the Householder
// reflection H(n) = I - v v^T / (1 + n_z), v = n + e_z, which maps e_z to -n:
//   u1 = e_x - v n_x / (1 + n_z),  u2 = e_y - v n_y / (1 + n_z).
// It is smooth everywhere except at n = -e_z; callers choose the sign of n so that
// n_z >= 0 (checked) and stay far from that point.

#include <Eigen/Core>

namespace calibproj::ba {

// Columns u1, u2: an orthonormal basis of the plane orthogonal to the unit vector n.
Eigen::Matrix<double, 3, 2> TangentBasis(const Eigen::Vector3d& n);

// Derivative of a u1 + b u2 with respect to n (n treated as a free 3-vector).
Eigen::Matrix3d TangentCombinationJacobian(const Eigen::Vector3d& n, double a, double b);

// Moves the unit vector n along the great circle of direction TangentBasis(n) * delta
// by the angle |delta|. The result is a unit vector.
Eigen::Vector3d SpherePlus(const Eigen::Vector3d& n, const Eigen::Vector2d& delta);

// Inverse of SpherePlus: the delta with SpherePlus(n, delta) = m for unit n, m.
Eigen::Vector2d SphereMinus(const Eigen::Vector3d& m, const Eigen::Vector3d& n);

// Smallest n_z for which TangentBasis is used; below it the basis is ill-conditioned.
constexpr double kMinSphereZ = -0.5;

}  // namespace calibproj::ba
