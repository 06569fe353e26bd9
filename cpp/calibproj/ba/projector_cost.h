#pragma once
// The projector in the bundle adjustment: every projected marker centre has a known
// projector pixel, and the projector maps its pixels onto each flat surface (the
// floor, a table top) by a homography composed with its lens's smooth distortion.
// A centre's plane coordinates are therefore tied to its projector pixel, even when
// one camera alone sees it.
//
// Projector pixels are used in normalised form: u~ = (p - image centre) / image width.
// The lens block (2) [k1, k2] undoes the projector lens's radial distortion about the
// image centre: u = u~ (1 + k1 r^2 + k2 r^4), r = |u~|. A surface's map block (8)
// [g11 g12 g13 g21 g22 g23 g31 g32] (g33 = 1) sends a point's plane coordinates (a, b)
// (the tangent basis of sphere.h, as the COPLANAR point block) to u:
//   u = (g11 a + g12 b + g13, g21 a + g22 b + g23) / (g31 a + g32 b + 1).
// Residual (2): weight * (G(a, b) - u), so that `weight` = projector width / the
// projector's noise in pixels, times the cameras' reference noise, makes it
// commensurate with the reprojection residuals.

#include <ceres/sized_cost_function.h>

#include <Eigen/Core>

namespace calibproj::ba {

using SurfaceMap = Eigen::Matrix<double, 8, 1>;

class ProjectorSurfaceCost final : public ceres::SizedCostFunction<2, 8, 2, 2> {
 public:
  ProjectorSurfaceCost(const Eigen::Vector2d& projector_normalised, double weight)
      : u_(projector_normalised), weight_(weight) {}
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

 private:
  const Eigen::Vector2d u_;
  const double weight_;
};

// u~ with the lens correction applied.
Eigen::Vector2d UndistortProjector(const Eigen::Vector2d& normalised, const Eigen::Vector2d& lens);

// G(a, b); false where the map's denominator vanishes.
bool ApplySurfaceMap(const SurfaceMap& map, const Eigen::Vector2d& ab, Eigen::Vector2d* u);

// Plane coordinates (a, b) of the undistorted projector coordinate u under `map`
// (the inverse homography); false where it is not defined.
bool InvertSurfaceMap(const SurfaceMap& map, const Eigen::Vector2d& u, Eigen::Vector2d* ab);

// Least-squares map from plane coordinates to undistorted projector coordinates
// (normalised DLT); false with fewer than 4 points or a degenerate configuration.
bool FitSurfaceMap(const std::vector<Eigen::Vector2d>& ab, const std::vector<Eigen::Vector2d>& u, SurfaceMap* map);

}  // namespace calibproj::ba
