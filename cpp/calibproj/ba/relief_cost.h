#pragma once
// A floor that is not quite flat. Real floors rise and fall by millimetres over a
// metre or two; a camera zoomed onto a patch of it cannot tell that patch's tilt from
// its own, so a model that holds every centre on one plane hands the camera the
// patch's slope as a rotation error. The relief lets the main plane's points leave the
// plane along its normal by a smooth height h(a, b) over a grid on the plane
// coordinates, with a Gaussian prior on every node's height: the
// cameras that see a centre from several directions measure h there, and where none
// does the prior keeps it near 0 and the covariance knows the tilt is uncertain.
//
// A point of the main plane [n, d] with relief is X = (d + h) n + a u1(n) + b u2(n):
// the plane's point seen through a plane moved by h. The height between the nodes is
// a uniform cubic B-spline (16 nodes per point: the grid's cells plus a ring of nodes
// around them) or bilinear (4 nodes: the cell's corners). A camera zoomed onto a
// patch sees its height at about a pixel per millimetre; a bilinear surface's kinks
// on a floor curved by 0.1 /m are a few tenths of a millimetre where the cubic's
// slope and curvature run on smoothly. ReliefReprojectionCost wraps a COPLANAR
// reprojection cost (pose 6, plane 4, point 2) and adds the node blocks (1 each) of
// the point's cell; its Jacobians follow from the wrapped cost's by the chain rule,
// so an analytic or an automatically differentiated cost serves alike.
//
// The projector sees a raised centre along its ray: the centre at plane coordinates
// (a, b) and height h lies on the ray through the plane point F where the projector's
// map places its pixel. With the projector's centre at height e over the plane above
// plane coordinates C, F = ((a, b) - h C / e) / (1 - h / e): a shift of about h / e times
// the distance to the projector's nadir, which on a 6 mm uneven floor bends the zoomed
// camera's patch by a few tenths of a millimetre, a tilt of 0.05 deg. ReliefProjectorCost
// wraps a ProjectorSurfaceCost with it; the projector's apex block (3) is
// [1 / e, C_a / e, C_b / e], refined with the relief (1 / e so that a distant projector
// is 0, not infinite).

#include <ceres/cost_function.h>
#include <ceres/sized_cost_function.h>

#include <Eigen/Core>
#include <array>
#include <memory>
#include <vector>

namespace calibproj::ba {

// The most nodes a point's height depends on (a cubic cell's 4 x 4).
inline constexpr int kMaxCellNodes = 16;

// Cells of side `spacing` on a regular grid over plane coordinates, cell (i, j) from
// origin + spacing * (i, j). Bilinear: node (i, j) is the corner at origin + spacing *
// (i, j); cubic: a B-spline control point at origin + spacing * (i - 1, j - 1), one
// ring more. Node (i, j) is stored at index j * columns() + i.
struct ReliefGrid {
  Eigen::Vector2d origin = Eigen::Vector2d::Zero();
  double spacing = 1.0;
  int cell_columns = 0;
  int cell_rows = 0;
  bool cubic = false;

  // A grid whose cells are `cells` across the larger extent of the central 98 % of
  // `ab` along either axis, covering them.
  static ReliefGrid Covering(const std::vector<Eigen::Vector2d>& ab, int cells, bool cubic);
  // Nodes per cell (4 or 16), along a row of nodes, in all.
  int cell_nodes() const { return cubic ? 16 : 4; }
  int columns() const { return cell_columns + (cubic ? 3 : 1); }
  int size() const { return cell_columns > 0 && cell_rows > 0 ? columns() * (cell_rows + (cubic ? 3 : 1)) : 0; }
  // The cell holding ab (the nearest cell for a point outside the grid): its node
  // indices, and the weights of ab and their derivatives along a and b (outside the
  // cell, the weights of its nearest edge point). Nodes row by row: (i, j), (i + 1, j),
  // ..., (i, j + 1), ...
  struct Cell {
    int count = 0;
    std::array<int, kMaxCellNodes> nodes{};
    std::array<double, kMaxCellNodes> weights{};
    std::array<Eigen::Vector2d, kMaxCellNodes> gradients{};
  };
  Cell CellOf(const Eigen::Vector2d& ab, int* cell_index = nullptr) const;
  Cell CellAt(int cell_index, const Eigen::Vector2d& ab) const;
  // The nodes of a cell, in the order of Cell::nodes.
  std::vector<int> NodesOf(int cell_index) const;
  // The height at ab of the cell's nodes in `heights` (all the grid's nodes).
  double HeightAt(int cell_index, const Eigen::Vector2d& ab, const double* heights) const;
};

class ReliefReprojectionCost final : public ceres::CostFunction {
 public:
  // Takes ownership of `plane_cost` (blocks pose 6, plane 4, point 2); `cell` is the
  // index of the grid cell whose nodes (grid.cell_nodes() blocks of 1 after the
  // point's) the point is given, kept while it moves.
  ReliefReprojectionCost(ceres::CostFunction* plane_cost, const ReliefGrid& grid, int cell);
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

 private:
  std::unique_ptr<ceres::CostFunction> plane_cost_;
  const ReliefGrid grid_;
  const int cell_;
};

class ReliefProjectorCost final : public ceres::CostFunction {
 public:
  // Takes ownership of `projector_cost` (blocks map 8, lens 2, point 2); adds the apex
  // (3) and the node blocks (1 each) of `cell`.
  ReliefProjectorCost(ceres::CostFunction* projector_cost, const ReliefGrid& grid, int cell);
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

 private:
  std::unique_ptr<ceres::CostFunction> projector_cost_;
  const ReliefGrid grid_;
  const int cell_;
};

// F of the comment above: where the projector's map must place a centre at plane
// coordinates ab and height h, for the apex [1 / e, C / e]; false where the centre is
// level with the projector.
bool ProjectorFootOf(const Eigen::Vector2d& ab, double h, const double* apex, Eigen::Vector2d* foot);

// A Gaussian prior on the apex: weights * (apex - mean), componentwise.
class ApexPriorCost final : public ceres::SizedCostFunction<3, 3> {
 public:
  ApexPriorCost(const Eigen::Vector3d& mean, const Eigen::Vector3d& weights) : mean_(mean), weights_(weights) {}
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

 private:
  const Eigen::Vector3d mean_;
  const Eigen::Vector3d weights_;
};

// The prior on one node's height: weight * h, weight = reference noise (px) / the
// expected root mean square height.
class ReliefPriorCost final : public ceres::SizedCostFunction<1, 1> {
 public:
  explicit ReliefPriorCost(double weight) : weight_(weight) {}
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

 private:
  const double weight_;
};

}  // namespace calibproj::ba
