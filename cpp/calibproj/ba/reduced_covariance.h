#pragma once
// The joint covariance of a solved bundle adjustment's camera-side blocks (poses,
// planes, projector maps, relief nodes: everything but the points), cross terms
// included, from the reduced camera system: the points are eliminated from the normal
// equations J^T J by their Schur complement, as the Schur linear solvers do, and the
// small dense system left is inverted. Cheaper than a generic covariance of every
// block (ceres::Covariance factors the whole Jacobian), and exact for the same problem.

#include <ceres/problem.h>

#include <Eigen/Core>
#include <functional>
#include <vector>

namespace calibproj::ba {

// Covariance, for residuals of unit variance, of the `kept` blocks in their tangent
// spaces and in the order given, with the `eliminated` blocks (each seen by residuals
// that involve no other eliminated block: the points) marginalised out. Every block
// must be a variable (not constant) block of `problem`, evaluated where it stands (an
// evaluation callback of the problem must be up to date: it is not called). The
// residual blocks are evaluated one by one, robust loss applied, and the system is
// gathered block by block: no Jacobian matrix is built.
// Throws std::runtime_error when the reduced system is singular (a gauge freedom left
// open, or blocks the residuals do not determine).
Eigen::MatrixXd ReducedCovariance(ceres::Problem* problem, const std::vector<double*>& eliminated,
                                  const std::vector<double*>& kept);

// Parameters the residuals depend on but the solve held ("consider" parameters: a lens
// refined elsewhere, whose own uncertainty is known there). `jacobian` gives, for a
// residual block, the first of the `columns` it depends on and its derivative by them
// (rows x width, of the residual before the robust loss: the loss is applied here as
// Ceres applies it to the other blocks' Jacobians); a width of 0: none.
struct ConsideredParameters {
  int columns = 0;
  std::function<int(ceres::ResidualBlockId id, Eigen::MatrixXd* jacobian)> jacobian;
};

struct ReducedSolution {
  Eigen::MatrixXd covariance;   // as ReducedCovariance
  // d kept / d considered (kept tangent entries x considered columns): how the solution
  // moves when the considered parameters do, the points re-solved with it.
  Eigen::MatrixXd sensitivity;
};

// ReducedCovariance, and the sensitivity of the kept blocks to the considered
// parameters: -S^-1 B, with S the reduced system and B the reduced cross terms between
// the kept blocks and the considered parameters.
ReducedSolution ReducedCovarianceWithSensitivity(ceres::Problem* problem, const std::vector<double*>& eliminated,
                                                 const std::vector<double*>& kept,
                                                 const ConsideredParameters& considered);

}  // namespace calibproj::ba
