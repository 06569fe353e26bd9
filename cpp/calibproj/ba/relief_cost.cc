#include "calibproj/ba/relief_cost.h"

#include <algorithm>
#include <cmath>

#include "calibproj/common/quantile.h"

namespace calibproj::ba {

namespace {

// The uniform B-spline's weights of the nodes before, at, after and two after a cell's
// start at t in [0, 1] of the cell, and their derivatives along t; bilinear: the first
// two.
void SplineWeights(bool cubic, double t, double* weights, double* derivatives) {
  if (!cubic) {
    weights[0] = 1.0 - t;
    weights[1] = t;
    derivatives[0] = -1.0;
    derivatives[1] = 1.0;
    return;
  }
  const double u = 1.0 - t;
  weights[0] = u * u * u / 6.0;
  weights[1] = (3.0 * t * t * t - 6.0 * t * t + 4.0) / 6.0;
  weights[2] = (-3.0 * t * t * t + 3.0 * t * t + 3.0 * t + 1.0) / 6.0;
  weights[3] = t * t * t / 6.0;
  derivatives[0] = -0.5 * u * u;
  derivatives[1] = 0.5 * (3.0 * t * t - 4.0 * t);
  derivatives[2] = 0.5 * (-3.0 * t * t + 2.0 * t + 1.0);
  derivatives[3] = 0.5 * t * t;
}

}  // namespace

ReliefGrid ReliefGrid::Covering(const std::vector<Eigen::Vector2d>& ab, int cells, bool cubic) {
  ReliefGrid grid;
  grid.cubic = cubic;
  if (ab.empty() || cells < 1) return grid;
  // The central 98 % of the points along each axis: a stray point far out does not
  // stretch the cells (it takes the height of the nearest edge).
  Eigen::Vector2d lower, upper;
  for (int axis = 0; axis < 2; ++axis) {
    std::vector<double> values;
    for (const Eigen::Vector2d& p : ab) values.push_back(p(axis));
    lower(axis) = Quantile(values, 0.01);
    upper(axis) = Quantile(values, 0.99);
  }
  const Eigen::Vector2d extent = upper - lower;
  grid.spacing = std::max(extent.maxCoeff() / cells, 1e-12);
  // Whole cells centred on the points' box.
  grid.cell_columns = std::max(1, static_cast<int>(std::ceil(extent(0) / grid.spacing - 1e-9)));
  grid.cell_rows = std::max(1, static_cast<int>(std::ceil(extent(1) / grid.spacing - 1e-9)));
  grid.origin = 0.5 * (lower + upper) - 0.5 * grid.spacing * Eigen::Vector2d(grid.cell_columns, grid.cell_rows);
  return grid;
}

ReliefGrid::Cell ReliefGrid::CellOf(const Eigen::Vector2d& ab, int* cell_index) const {
  const Eigen::Vector2d local = (ab - origin) / spacing;
  const int i = std::clamp(static_cast<int>(std::floor(local(0))), 0, cell_columns - 1);
  const int j = std::clamp(static_cast<int>(std::floor(local(1))), 0, cell_rows - 1);
  const int index = j * cell_columns + i;
  if (cell_index != nullptr) *cell_index = index;
  return CellAt(index, ab);
}

std::vector<int> ReliefGrid::NodesOf(int cell_index) const {
  const Cell cell = CellAt(cell_index, origin);
  return std::vector<int>(cell.nodes.begin(), cell.nodes.begin() + cell.count);
}

ReliefGrid::Cell ReliefGrid::CellAt(int cell_index, const Eigen::Vector2d& ab) const {
  const int i = cell_index % cell_columns;
  const int j = cell_index / cell_columns;
  // Outside its cell a point takes the height of the cell's nearest edge: a point far
  // off the grid (an outlier) must not see the cell's slope extrapolated.
  const double s_free = (ab(0) - origin(0)) / spacing - i;
  const double t_free = (ab(1) - origin(1)) / spacing - j;
  const double s = std::clamp(s_free, 0.0, 1.0);
  const double t = std::clamp(t_free, 0.0, 1.0);
  const double ks = s == s_free ? 1.0 / spacing : 0.0;
  const double kt = t == t_free ? 1.0 / spacing : 0.0;
  double ws[4], ds[4], wt[4], dt[4];
  SplineWeights(cubic, s, ws, ds);
  SplineWeights(cubic, t, wt, dt);
  // The cell's first node is (i, j) whichever the shape: a cubic grid's ring of nodes
  // puts the node before the cell's start there.
  const int across = cubic ? 4 : 2;
  Cell cell;
  cell.count = across * across;
  for (int n = 0; n < across; ++n) {
    for (int m = 0; m < across; ++m) {
      const int k = n * across + m;
      cell.nodes[k] = (j + n) * columns() + i + m;
      cell.weights[k] = ws[m] * wt[n];
      cell.gradients[k] = Eigen::Vector2d(ds[m] * wt[n] * ks, ws[m] * dt[n] * kt);
    }
  }
  return cell;
}

double ReliefGrid::HeightAt(int cell_index, const Eigen::Vector2d& ab, const double* heights) const {
  const Cell cell = CellAt(cell_index, ab);
  double h = 0.0;
  for (int k = 0; k < cell.count; ++k) h += cell.weights[k] * heights[cell.nodes[k]];
  return h;
}

ReliefReprojectionCost::ReliefReprojectionCost(ceres::CostFunction* plane_cost, const ReliefGrid& grid, int cell)
    : plane_cost_(plane_cost), grid_(grid), cell_(cell) {
  set_num_residuals(2);
  *mutable_parameter_block_sizes() = {6, 4, 2};
  mutable_parameter_block_sizes()->resize(3 + grid.cell_nodes(), 1);
}

bool ReliefReprojectionCost::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  const double* plane = parameters[1];
  const Eigen::Map<const Eigen::Vector2d> ab(parameters[2]);
  const ReliefGrid::Cell cell = grid_.CellAt(cell_, ab);
  double h = 0.0;
  for (int k = 0; k < cell.count; ++k) h += cell.weights[k] * parameters[3 + k][0];
  const double moved_plane[4] = {plane[0], plane[1], plane[2], plane[3] + h};
  const double* inner_parameters[3] = {parameters[0], moved_plane, parameters[2]};
  if (jacobians == nullptr) return plane_cost_->Evaluate(inner_parameters, residuals, nullptr);

  // d(residual)/d(plane) is needed for the plane, the point and the nodes alike.
  bool height_moves = jacobians[1] != nullptr || jacobians[2] != nullptr;
  for (int k = 0; k < cell.count; ++k) height_moves |= jacobians[3 + k] != nullptr;
  Eigen::Matrix<double, 2, 4, Eigen::RowMajor> J_plane;
  Eigen::Matrix<double, 2, 2, Eigen::RowMajor> J_ab;
  double* inner_jacobians[3] = {jacobians[0], height_moves ? J_plane.data() : nullptr,
                                jacobians[2] != nullptr ? J_ab.data() : nullptr};
  if (!plane_cost_->Evaluate(inner_parameters, residuals, inner_jacobians)) return false;
  using Map2x4 = Eigen::Map<Eigen::Matrix<double, 2, 4, Eigen::RowMajor>>;
  using Map2x2 = Eigen::Map<Eigen::Matrix<double, 2, 2, Eigen::RowMajor>>;
  if (jacobians[1] != nullptr) Map2x4{jacobians[1]} = J_plane;
  const Eigen::Vector2d d_offset = J_plane.col(3);
  if (jacobians[2] != nullptr) {
    Eigen::Vector2d dh_dab = Eigen::Vector2d::Zero();
    for (int k = 0; k < cell.count; ++k) dh_dab += parameters[3 + k][0] * cell.gradients[k];
    Map2x2{jacobians[2]} = J_ab + d_offset * dh_dab.transpose();
  }
  for (int k = 0; k < cell.count; ++k) {
    if (jacobians[3 + k] != nullptr) Eigen::Map<Eigen::Vector2d>{jacobians[3 + k]} = d_offset * cell.weights[k];
  }
  return true;
}

ReliefProjectorCost::ReliefProjectorCost(ceres::CostFunction* projector_cost, const ReliefGrid& grid, int cell)
    : projector_cost_(projector_cost), grid_(grid), cell_(cell) {
  set_num_residuals(2);
  *mutable_parameter_block_sizes() = {8, 2, 2, 3};
  mutable_parameter_block_sizes()->resize(4 + grid.cell_nodes(), 1);
}

bool ProjectorFootOf(const Eigen::Vector2d& ab, double h, const double* apex, Eigen::Vector2d* foot) {
  const double level = 1.0 - apex[0] * h;
  if (!(std::abs(level) > 1e-9)) return false;
  *foot = (ab - h * Eigen::Vector2d(apex[1], apex[2])) / level;
  return foot->allFinite();
}

bool ReliefProjectorCost::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  const Eigen::Map<const Eigen::Vector2d> ab(parameters[2]);
  const double* apex = parameters[3];
  const ReliefGrid::Cell cell = grid_.CellAt(cell_, ab);
  double h = 0.0;
  for (int k = 0; k < cell.count; ++k) h += cell.weights[k] * parameters[4 + k][0];
  Eigen::Vector2d foot;
  if (!ProjectorFootOf(ab, h, apex, &foot)) return false;
  const double* inner_parameters[3] = {parameters[0], parameters[1], foot.data()};
  if (jacobians == nullptr) return projector_cost_->Evaluate(inner_parameters, residuals, nullptr);

  Eigen::Matrix<double, 2, 2, Eigen::RowMajor> J_foot;
  double* inner_jacobians[3] = {jacobians[0], jacobians[1], J_foot.data()};
  if (!projector_cost_->Evaluate(inner_parameters, residuals, inner_jacobians)) return false;
  const double level = 1.0 - apex[0] * h;
  // dF/dh = (F / e - C / e) / level, with F = foot.
  const Eigen::Vector2d dfoot_dh = (apex[0] * foot - Eigen::Vector2d(apex[1], apex[2])) / level;
  const Eigen::Vector2d d_height = J_foot * dfoot_dh;
  if (jacobians[2] != nullptr) {
    Eigen::Vector2d dh_dab = Eigen::Vector2d::Zero();
    for (int k = 0; k < cell.count; ++k) dh_dab += parameters[4 + k][0] * cell.gradients[k];
    Eigen::Map<Eigen::Matrix<double, 2, 2, Eigen::RowMajor>>{jacobians[2]} =
        J_foot / level + d_height * dh_dab.transpose();
  }
  if (jacobians[3] != nullptr) {
    Eigen::Matrix<double, 2, 3> dfoot_dapex;
    dfoot_dapex << h * foot / level, -h / level * Eigen::Matrix2d::Identity();
    Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>>{jacobians[3]} = J_foot * dfoot_dapex;
  }
  for (int k = 0; k < cell.count; ++k) {
    if (jacobians[4 + k] != nullptr) Eigen::Map<Eigen::Vector2d>{jacobians[4 + k]} = d_height * cell.weights[k];
  }
  return true;
}

bool ApexPriorCost::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  const Eigen::Map<const Eigen::Vector3d> apex(parameters[0]);
  Eigen::Map<Eigen::Vector3d>{residuals} = weights_.cwiseProduct(apex - mean_);
  if (jacobians != nullptr && jacobians[0] != nullptr) {
    Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>{jacobians[0]} = weights_.asDiagonal();
  }
  return true;
}

bool ReliefPriorCost::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  residuals[0] = weight_ * parameters[0][0];
  if (jacobians != nullptr && jacobians[0] != nullptr) jacobians[0][0] = weight_;
  return true;
}

}  // namespace calibproj::ba
