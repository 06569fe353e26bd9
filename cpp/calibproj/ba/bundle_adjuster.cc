#include "calibproj/ba/bundle_adjuster.h"

#include <ceres/ceres.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include "calibproj/ba/manifolds.h"
#include "calibproj/ba/reduced_covariance.h"
#include "calibproj/ba/relief_cost.h"
#include "calibproj/ba/reprojection_cost.h"
#include "calibproj/ba/rotation_cache.h"
#include "calibproj/ba/rotation.h"
#include "calibproj/ba/sphere.h"
#include "calibproj/common/limits.h"

namespace calibproj::ba {

namespace {

std::string Str(double v) { return std::to_string(v); }
std::string Str(int v) { return std::to_string(v); }

[[noreturn]] void Fail(const std::string& message) { throw std::invalid_argument(message); }

void Require(bool condition, const std::string& message) {
  if (!condition) Fail(message);
}

// Rigid change of world frame X' = R X + t, applied to poses, points and the plane.
struct FrameChange {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
};

Eigen::Matrix3d PoseRotation(const PoseMatrix& poses, int c) {
  return RotationFromAngleAxis(poses.row(c).head<3>().transpose());
}

// A plane [n, d] under X' = R X + t, and back.
Eigen::Vector4d PlaneToGauge(const Eigen::Vector4d& plane, const FrameChange& change) {
  const Eigen::Vector3d n = change.R * plane.head<3>();
  return (Eigen::Vector4d() << n, plane(3) + n.dot(change.t)).finished();
}

Eigen::Vector4d PlaneFromGauge(const Eigen::Vector4d& plane, const FrameChange& change) {
  const Eigen::Vector3d n_gauge = plane.head<3>();
  return (Eigen::Vector4d() << change.R.transpose() * n_gauge, plane(3) - n_gauge.dot(change.t)).finished();
}

// Moves the data into the gauge camera's frame (gauge pose becomes the identity).
Data ToGaugeFrame(const Data& data, const FrameChange& change) {
  Data out = data;
  for (int c = 0; c < data.poses.rows(); ++c) {
    const Eigen::Matrix3d Rc = PoseRotation(data.poses, c) * change.R.transpose();
    const Eigen::Vector3d tc = data.poses.row(c).tail<3>().transpose() - Rc * change.t;
    out.poses.row(c).head<3>() = AngleAxisFromRotation(Rc).transpose();
    out.poses.row(c).tail<3>() = tc.transpose();
  }
  for (int p = 0; p < data.points.rows(); ++p) {
    out.points.row(p) = (change.R * data.points.row(p).transpose() + change.t).transpose();
  }
  out.plane = PlaneToGauge(data.plane, change);
  for (int k = 0; k < data.more_planes.rows(); ++k) {
    out.more_planes.row(k) = PlaneToGauge(data.more_planes.row(k).transpose(), change).transpose();
  }
  return out;
}

// Inverse of ToGaugeFrame for poses, points and planes.
void FromGaugeFrame(const FrameChange& change, PoseMatrix* poses, PointMatrix* points, Eigen::Vector4d* plane,
                    PlaneMatrix* more_planes) {
  for (int c = 0; c < poses->rows(); ++c) {
    const Eigen::Matrix3d Rc_gauge = PoseRotation(*poses, c);
    const Eigen::Vector3d tc = poses->row(c).tail<3>().transpose() + Rc_gauge * change.t;
    poses->row(c).head<3>() = AngleAxisFromRotation(Rc_gauge * change.R).transpose();
    poses->row(c).tail<3>() = tc.transpose();
  }
  for (int p = 0; p < points->rows(); ++p) {
    points->row(p) = (change.R.transpose() * (points->row(p).transpose() - change.t)).transpose();
  }
  *plane = PlaneFromGauge(*plane, change);
  for (int k = 0; k < more_planes->rows(); ++k) {
    more_planes->row(k) = PlaneFromGauge(more_planes->row(k).transpose(), change).transpose();
  }
}

ceres::LinearSolverType CeresLinearSolver(LinearSolver solver, int num_cameras) {
  switch (solver) {
    case LinearSolver::kDenseSchur: return ceres::DENSE_SCHUR;
    case LinearSolver::kSparseSchur: return ceres::SPARSE_SCHUR;
    case LinearSolver::kIterativeSchur: return ceres::ITERATIVE_SCHUR;
    case LinearSolver::kDenseQr: return ceres::DENSE_QR;
    case LinearSolver::kSparseNormalCholesky: return ceres::SPARSE_NORMAL_CHOLESKY;
    case LinearSolver::kAuto: break;
  }
  // Measured on the paper rig (tools/bench/ba_speed.py): the reduced camera system
  // is small and dense, so dense Schur wins until it is a few hundred columns wide.
  return num_cameras <= 60 ? ceres::DENSE_SCHUR : ceres::SPARSE_SCHUR;
}

int FarthestCamera(const PoseMatrix& poses_in_gauge_frame, int gauge_camera) {
  int best = -1;
  double best_distance = 0.0;
  for (int c = 0; c < poses_in_gauge_frame.rows(); ++c) {
    const double distance = poses_in_gauge_frame.row(c).tail<3>().norm();
    if (c != gauge_camera && distance > best_distance) {
      best = c;
      best_distance = distance;
    }
  }
  return best;
}

// The parameter blocks the solver works on, in the gauge frame.
//
// Every point's block is a row of one matrix: a free point its 3 coordinates, a point
// on a plane its 2 coordinates in the plane's tangent basis (the third entry unused).
// Ceres orders the blocks of one elimination group by address, so blocks of one array
// are ordered the same in every run, and results repeat to the last bit whatever the
// heap layout.
struct Parameters {
  PoseMatrix poses;
  PointMatrix points;
  Eigen::Vector4d plane;
  PlaneMatrix more_planes;
  std::vector<int> point_plane;  // per point: 0 plane, k >= 1 more_planes row k - 1, -1 free
  // Projector: per plane its map (valid or not) and the lens. Kept in this struct, not
  // on the heap: Ceres's covariance orders blocks by address, and these must come after
  // the heap arrays' in every process for the results to repeat to the bit.
  std::array<double, 8 * kMaxProjectorSurfaces> map_storage{};
  std::vector<bool> map_valid;
  Eigen::Vector2d lens = Eigen::Vector2d::Zero();

  double* Map(int k) { return map_storage.data() + 8 * k; }

  // The main plane's relief (relief_cost.h): node heights, kept here for the same
  // reason as the maps; per point its grid cell, -1 for a point without relief.
  ReliefGrid relief_grid;
  std::array<double, (kMaxReliefCells + 3) * (kMaxReliefCells + 3)> relief_storage{};
  std::vector<int> relief_cell;

  // The projector's apex [1 / e, C / e] (relief_cost.h), refined where the main plane has
  // both a relief and a projector map; its prior's mean and weights.
  Eigen::Vector3d apex = Eigen::Vector3d::Zero();
  Eigen::Vector3d apex_mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d apex_weights = Eigen::Vector3d::Zero();
  bool has_apex = false;

  bool HasRelief() const { return relief_grid.size() > 0; }
  double* ReliefNode(int node) { return relief_storage.data() + node; }
  // The relief's height under point p (0 without one).
  double ReliefHeight(int p) const {
    if (relief_cell.empty() || relief_cell[p] < 0) return 0.0;
    return relief_grid.HeightAt(relief_cell[p], points.row(p).head<2>().transpose(), relief_storage.data());
  }

  double* Plane(int k) { return k == 0 ? plane.data() : more_planes.row(k - 1).data(); }
  double* PointBlock(int p) { return points.row(p).data(); }
};

// Unit normal; for the main plane pointing away from the gauge camera (d > 0), for the
// others upwards or sideways (n_z >= 0): either way far from the tangent basis's
// singular direction -e_z.
Eigen::Vector4d OrientedPlane(Eigen::Vector4d plane, bool main) {
  plane /= plane.head<3>().norm();  // unit normal, offset in world units
  if (main ? plane(3) < 0.0 : plane(2) < 0.0) plane = -plane;
  return plane;
}

bool HasProjectorPixel(const Data& data, int p) {
  return data.projector.rows() > 0 && data.projector.row(p).allFinite();
}

bool HasProjectorMap(const Parameters& params, int k) {
  return k >= 0 && k < static_cast<int>(params.map_valid.size()) && params.map_valid[k];
}

// Per plane, the map that best fits its points' plane coordinates to their projector
// pixels; valid for the planes with min_projector_points such points.
void InitialProjectorMaps(const Data& data, const Options& options, Parameters* params) {
  const int num_planes = std::min(1 + static_cast<int>(params->more_planes.rows()), kMaxProjectorSurfaces);
  params->map_valid.assign(num_planes, false);
  params->lens = data.projector_lens;
  if (data.projector.rows() == 0 || !(data.projector_weight > 0.0)) return;
  std::vector<std::vector<Eigen::Vector2d>> ab(num_planes), u(num_planes);
  for (int p = 0; p < static_cast<int>(params->points.rows()); ++p) {
    const int k = params->point_plane[p];
    if (k < 0 || k >= num_planes || !HasProjectorPixel(data, p)) continue;
    ab[k].push_back(params->points.row(p).head<2>().transpose());
    u[k].push_back(UndistortProjector(data.projector.row(p).transpose(), params->lens));
  }
  for (int k = 0; k < num_planes; ++k) {
    if (static_cast<int>(ab[k].size()) < options.min_projector_points) continue;
    SurfaceMap map;
    if (!FitSurfaceMap(ab[k], u[k], &map)) continue;
    Eigen::Map<SurfaceMap>(params->Map(k)) = map;
    params->map_valid[k] = true;
  }
}

// A flat relief over the main plane's points, each given the cell it lies in.
void InitialRelief(const Options& options, Parameters* params) {
  std::vector<Eigen::Vector2d> ab;
  for (int p = 0; p < static_cast<int>(params->points.rows()); ++p) {
    if (params->point_plane[p] == 0) ab.push_back(params->points.row(p).head<2>().transpose());
  }
  if (ab.size() < 2) return;
  params->relief_grid = ReliefGrid::Covering(ab, options.relief_cells, options.relief_cubic);
  params->relief_cell.assign(params->points.rows(), -1);
  for (int p = 0; p < static_cast<int>(params->points.rows()); ++p) {
    if (params->point_plane[p] == 0) params->relief_grid.CellOf(params->points.row(p).head<2>(), &params->relief_cell[p]);
  }
}

// The apex's prior: the projector hangs as high above the plane as the highest camera
// (half of that either way), above the middle of the plane's points (half their extent
// either way), with residuals in units of the reference noise.
void InitialApex(const Data& data, Parameters* params) {
  if (!params->HasRelief() || !HasProjectorMap(*params, 0) || !(data.apex_prior_px > 0.0)) return;
  const Eigen::Vector3d n = params->plane.head<3>();
  double height = 0.0;
  for (int c = 0; c < params->poses.rows(); ++c) {
    const Eigen::Vector3d w = params->poses.row(c).head<3>().transpose();
    const Eigen::Vector3d centre = -RotationFromAngleAxis(w).transpose() * params->poses.row(c).tail<3>().transpose();
    const double offset = n.dot(centre) - params->plane(3);
    if (std::abs(offset) > std::abs(height)) height = offset;
  }
  if (!(std::abs(height) > 0.0)) return;
  Eigen::Vector2d middle = Eigen::Vector2d::Zero();
  int count = 0;
  for (int p = 0; p < static_cast<int>(params->points.rows()); ++p) {
    if (params->point_plane[p] != 0) continue;
    middle += params->points.row(p).head<2>().transpose();
    ++count;
  }
  middle /= std::max(count, 1);
  const ReliefGrid& grid = params->relief_grid;
  const double extent = grid.spacing * std::max(grid.cell_columns, grid.cell_rows);
  params->apex_mean << 1.0 / height, middle / height;
  const double beta_sigma = 0.5 * extent / std::abs(height);
  params->apex_weights << data.apex_prior_px / (0.5 / std::abs(height)), Eigen::Vector2d::Constant(data.apex_prior_px / beta_sigma);
  params->apex = params->apex_mean;
  params->has_apex = true;
}

Parameters InitialParameters(const Data& gauge_data, const Options& options) {
  Parameters params;
  params.poses = gauge_data.poses;
  params.plane = gauge_data.plane;
  params.points = gauge_data.points;
  const int num_points = static_cast<int>(gauge_data.points.rows());
  if (options.model == Model::kFree) {
    params.point_plane.assign(num_points, -1);
    return params;
  }
  params.point_plane.assign(num_points, 0);
  for (int p = 0; p < gauge_data.point_plane.size(); ++p) params.point_plane[p] = gauge_data.point_plane(p);
  params.plane = OrientedPlane(params.plane, true);
  Require(params.plane(2) > kMinSphereZ, "plane: seen edge-on or from behind by the gauge camera");
  params.more_planes = gauge_data.more_planes;
  for (int k = 0; k < params.more_planes.rows(); ++k) {
    params.more_planes.row(k) = OrientedPlane(params.more_planes.row(k).transpose(), false).transpose();
  }
  for (int p = 0; p < num_points; ++p) {
    if (params.point_plane[p] < 0) continue;
    const Eigen::Matrix<double, 3, 2> B = TangentBasis(Eigen::Map<const Eigen::Vector3d>(params.Plane(params.point_plane[p])));
    params.points.row(p) << (B.transpose() * gauge_data.points.row(p).transpose()).transpose(), 0.0;
  }
  InitialProjectorMaps(gauge_data, options, &params);
  if (gauge_data.relief_weight > 0.0) InitialRelief(options, &params);
  InitialApex(gauge_data, &params);
  return params;
}

void CopyPointsOut(Parameters& params, PointMatrix* points) {
  *points = params.points;
  for (int p = 0; p < points->rows(); ++p) {
    const int k = params.point_plane[p];
    if (k < 0) continue;
    const Eigen::Vector4d raised = Eigen::Map<const Eigen::Vector4d>(params.Plane(k)) +
                                   Eigen::Vector4d(0.0, 0.0, 0.0, params.ReliefHeight(p));
    points->row(p) = PointOnPlane(raised.data(), params.points.row(p).data()).transpose();
  }
}


std::unique_ptr<ceres::Manifold> ScaleGaugeManifold(const Parameters& params, int camera) {
  return std::make_unique<FixedDistancePoseManifold>(params.poses.row(camera).tail<3>().transpose());
}

struct Gauge {
  int camera = -1;
  int scale_camera = -1;
  bool fixed = false;  // poses and points both refined: the gauge must be removed
};

// Point p is on the main plane's relief and the projector sees it along its ray.
bool RaisedForProjector(const Parameters& params, int p) {
  return params.has_apex && params.point_plane[p] == 0 && !params.relief_cell.empty() && params.relief_cell[p] >= 0;
}

// One residual per point with a projector pixel on a plane with a valid map; returns
// how many.
int AddProjectorTerms(const Data& data, Parameters& params, ceres::LossFunction* loss, ceres::Problem* problem,
                      ceres::ParameterBlockOrdering* ordering) {
  int terms = 0;
  for (int p = 0; p < static_cast<int>(params.points.rows()); ++p) {
    const int k = params.point_plane[p];
    if (!HasProjectorMap(params, k) || !HasProjectorPixel(data, p)) continue;
    const double weight =
        data.projector_weight * (data.projector_point_weights.size() > 0 ? data.projector_point_weights(p) : 1.0);
    auto* cost = new ProjectorSurfaceCost(data.projector.row(p).transpose(), weight);
    if (RaisedForProjector(params, p)) {
      std::vector<double*> blocks = {params.Map(k), params.lens.data(), params.PointBlock(p), params.apex.data()};
      for (int node : params.relief_grid.NodesOf(params.relief_cell[p])) blocks.push_back(params.ReliefNode(node));
      problem->AddResidualBlock(new ReliefProjectorCost(cost, params.relief_grid, params.relief_cell[p]), loss, blocks);
    } else {
      problem->AddResidualBlock(cost, loss, params.Map(k), params.lens.data(), params.PointBlock(p));
    }
    ++terms;
  }
  if (terms == 0) return 0;
  // Groups of their own after the planes': blocks of one group are ordered by address,
  // and the lens does not live in the maps' array (results must repeat to the bit).
  const int num_planes = 1 + static_cast<int>(params.more_planes.rows());
  for (int k = 0; k < static_cast<int>(params.map_valid.size()); ++k) {
    if (params.map_valid[k]) ordering->AddElementToGroup(params.Map(k), 2 + num_planes);
  }
  ordering->AddElementToGroup(params.lens.data(), 3 + num_planes);
  if (problem->HasParameterBlock(params.apex.data())) {
    problem->AddResidualBlock(new ApexPriorCost(params.apex_mean, params.apex_weights), nullptr, params.apex.data());
    ordering->AddElementToGroup(params.apex.data(), 3 + num_planes);
  }
  return terms;
}

// Every relief node's prior, the nodes in a group of their own after the projector's.
void AddReliefPrior(const Data& data, Parameters& params, ceres::Problem* problem,
                    ceres::ParameterBlockOrdering* ordering) {
  const int num_planes = 1 + static_cast<int>(params.more_planes.rows());
  for (int node = 0; node < params.relief_grid.size(); ++node) {
    problem->AddResidualBlock(new ReliefPriorCost(data.relief_weight), nullptr, params.ReliefNode(node));
    ordering->AddElementToGroup(params.ReliefNode(node), 4 + num_planes);
  }
}

// The loss of each camera's residuals and of the projector's. Each is a wrapper when
// the covariance discounts shared errors, so that its weight can change after the solve.
struct GroupLosses {
  ceres::LossFunction* loss = nullptr;  // the robust loss (nullptr: none), not owned
  std::vector<std::unique_ptr<ceres::LossFunction>> cameras;  // empty: `loss` for every camera
  std::unique_ptr<ceres::LossFunctionWrapper> projector;     // nullptr: `loss`
  ceres::LossFunction* Camera(int c) const { return cameras.empty() ? loss : cameras[c].get(); }
  ceres::LossFunction* Projector() const { return projector ? projector.get() : loss; }
};

double CameraWeight(const Data& data, int c) { return data.camera_weights.size() == 0 ? 1.0 : data.camera_weights(c); }

std::unique_ptr<ceres::LossFunction> WeightedLoss(ceres::LossFunction* loss, double weight) {
  return std::make_unique<ceres::ScaledLoss>(loss, weight * weight, ceres::DO_NOT_TAKE_OWNERSHIP);
}

GroupLosses MakeGroupLosses(const Data& data, ceres::LossFunction* loss, bool adjustable) {
  GroupLosses losses;
  losses.loss = loss;
  const int num_cameras = static_cast<int>(data.intrinsics.size());
  if (data.camera_weights.size() == 0 && !adjustable) return losses;
  for (int c = 0; c < num_cameras; ++c) {
    std::unique_ptr<ceres::LossFunction> weighted = WeightedLoss(loss, CameraWeight(data, c));
    if (adjustable) weighted = std::make_unique<ceres::LossFunctionWrapper>(weighted.release(), ceres::TAKE_OWNERSHIP);
    losses.cameras.push_back(std::move(weighted));
  }
  if (adjustable) {
    losses.projector =
        std::make_unique<ceres::LossFunctionWrapper>(WeightedLoss(loss, 1.0).release(), ceres::TAKE_OWNERSHIP);
  }
  return losses;
}

// Errors that one group of residuals shares are not averaged away by their number: a
// group of N residuals with correlation rho carries the information of N / (1 + (N - 1)
// rho) independent ones. The covariance sees each group's weight divided accordingly.
// With `cameras` off, only the projector's.
void DiscountSharedErrors(const Data& data, double correlation, int projector_terms, bool cameras,
                          GroupLosses* losses) {
  const auto discount = [&](int n) { return 1.0 / std::sqrt(1.0 + std::max(0, n - 1) * correlation); };
  std::vector<int> observations(losses->cameras.size(), 0);
  for (int i = 0; i < data.camera_index.size(); ++i) ++observations[data.camera_index(i)];
  for (size_t c = 0; c < losses->cameras.size() && cameras; ++c) {
    const double w = CameraWeight(data, static_cast<int>(c)) * discount(observations[c]);
    static_cast<ceres::LossFunctionWrapper*>(losses->cameras[c].get())
        ->Reset(WeightedLoss(losses->loss, w).release(), ceres::TAKE_OWNERSHIP);
  }
  losses->projector->Reset(WeightedLoss(losses->loss, discount(projector_terms)).release(), ceres::TAKE_OWNERSHIP);
}

// Returns the number of projector terms.
int BuildProblem(const Data& data, const Options& options, const Gauge& gauge, Parameters& params,
                 const CostFactory& make_cost, const RotationCache* rotations, const GroupLosses& losses,
                 ceres::Problem* problem, ceres::ParameterBlockOrdering* ordering,
                 std::vector<ceres::ResidualBlockId>* observation_blocks) {
  const bool coplanar = options.model == Model::kCoplanar;
  for (int p = 0; p < static_cast<int>(data.points.rows()); ++p) {
    problem->AddParameterBlock(params.PointBlock(p), params.point_plane[p] < 0 ? 3 : 2);
    ordering->AddElementToGroup(params.PointBlock(p), 0);
  }
  for (int c = 0; c < params.poses.rows(); ++c) {
    double* pose = params.poses.row(c).data();
    if (gauge.fixed && c == gauge.scale_camera) {
      problem->AddParameterBlock(pose, 6, new PaddedManifold(ScaleGaugeManifold(params, c), 1));
    } else {
      problem->AddParameterBlock(pose, 6);
    }
    ordering->AddElementToGroup(pose, 1);
  }
  const int num_planes = coplanar ? 1 + static_cast<int>(params.more_planes.rows()) : 0;
  for (int k = 0; k < num_planes; ++k) {
    double* plane = params.Plane(k);
    // Only the main plane's offset carries the scale gauge.
    problem->AddParameterBlock(plane, 4, new PlaneManifold(Eigen::Map<const Eigen::Vector3d>(plane),
                                                           /*fix_offset=*/k == 0 && gauge.fixed));
    ordering->AddElementToGroup(plane, 2 + k);  // a group each: the planes lie in different arrays
  }
  for (int i = 0; i < data.camera_index.size(); ++i) {
    ceres::LossFunction* camera_loss = losses.Camera(data.camera_index(i));
    double* pose = params.poses.row(data.camera_index(i)).data();
    const int p = data.point_index(i);
    const int camera = data.camera_index(i);
    const int on_plane = params.point_plane[p];
    ceres::CostFunction* cost = make_cost(on_plane < 0 ? Model::kFree : Model::kCoplanar, data.intrinsics[camera],
                                          data.observed.row(i).transpose(),
                                          rotations != nullptr ? rotations->Entry(camera) : nullptr);
    if (on_plane >= 0 && !params.relief_cell.empty() && params.relief_cell[p] >= 0) {
      std::vector<double*> blocks = {pose, params.Plane(on_plane), params.PointBlock(p)};
      for (int node : params.relief_grid.NodesOf(params.relief_cell[p])) blocks.push_back(params.ReliefNode(node));
      observation_blocks->push_back(problem->AddResidualBlock(
          new ReliefReprojectionCost(cost, params.relief_grid, params.relief_cell[p]), camera_loss, blocks));
    } else if (on_plane >= 0) {
      observation_blocks->push_back(
          problem->AddResidualBlock(cost, camera_loss, pose, params.Plane(on_plane), params.PointBlock(p)));
    } else {
      observation_blocks->push_back(problem->AddResidualBlock(cost, camera_loss, pose, params.PointBlock(p)));
    }
  }
  const int projector_terms = AddProjectorTerms(data, params, losses.Projector(), problem, ordering);
  AddReliefPrior(data, params, problem, ordering);
  if (!options.refine_poses) {
    for (int c = 0; c < params.poses.rows(); ++c) problem->SetParameterBlockConstant(params.poses.row(c).data());
  } else if (gauge.fixed) {
    problem->SetParameterBlockConstant(params.poses.row(gauge.camera).data());
  }
  if (!options.refine_points) {
    for (int p = 0; p < static_cast<int>(data.points.rows()); ++p) {
      problem->SetParameterBlockConstant(params.PointBlock(p));
    }
    for (int k = 0; k < num_planes; ++k) problem->SetParameterBlockConstant(params.Plane(k));
    for (int node = 0; node < params.relief_grid.size(); ++node) {
      problem->SetParameterBlockConstant(params.ReliefNode(node));
    }
    if (problem->HasParameterBlock(params.apex.data())) problem->SetParameterBlockConstant(params.apex.data());
  }
  return projector_terms;
}

// Result fields of the projector: maps in the caller's frame, lens, residuals.
void CopyProjectorOut(const Data& data, Parameters& params, const FrameChange& change, Result* result) {
  result->projector_lens = params.lens;
  result->projector_surfaces.assign(params.map_valid.size(), ProjectorSurface());
  for (size_t k = 0; k < params.map_valid.size(); ++k) {
    if (!params.map_valid[k]) continue;
    const double* plane = params.Plane(static_cast<int>(k));
    const Eigen::Map<const Eigen::Vector3d> n(plane);
    Eigen::Matrix3d E;
    E << TangentBasis(n), plane[3] * n;
    ProjectorSurface& surface = result->projector_surfaces[k];
    surface.valid = true;
    surface.map = Eigen::Map<const SurfaceMap>(params.Map(static_cast<int>(k)));
    surface.world_from_plane = change.R.transpose() * (E - change.t * Eigen::RowVector3d(0.0, 0.0, 1.0));
    if (k == 0 && params.has_apex && std::abs(params.apex(0)) > 0.0) {
      const double height = 1.0 / params.apex(0);
      result->projector_centre = surface.world_from_plane * Eigen::Vector3d(params.apex(1) * height, params.apex(2) * height, 1.0) +
                                 change.R.transpose() * (height * n);
    }
  }
  const int num_points = static_cast<int>(params.points.rows());
  result->projector_residuals = PixelMatrix::Constant(num_points, 2, std::numeric_limits<double>::quiet_NaN());
  for (int p = 0; p < num_points; ++p) {
    const int k = params.point_plane[p];
    if (!HasProjectorMap(params, k) || !HasProjectorPixel(data, p)) continue;
    const ProjectorSurfaceCost cost(data.projector.row(p).transpose(), 1.0);
    Eigen::Vector2d foot = params.points.row(p).head<2>().transpose();
    if (RaisedForProjector(params, p) && !ProjectorFootOf(foot, params.ReliefHeight(p), params.apex.data(), &foot)) continue;
    const double* blocks[3] = {params.Map(k), params.lens.data(), foot.data()};
    double r[2];
    if (cost.Evaluate(blocks, r, nullptr)) result->projector_residuals.row(p) << r[0], r[1];
    ++result->projector_terms;
  }
}

ceres::Solver::Options SolverOptions(const Options& options, int num_cameras,
                                     std::shared_ptr<ceres::ParameterBlockOrdering> ordering) {
  ceres::Solver::Options solver;
  solver.linear_solver_type = CeresLinearSolver(options.linear_solver, num_cameras);
  if (solver.linear_solver_type == ceres::ITERATIVE_SCHUR) solver.preconditioner_type = ceres::SCHUR_JACOBI;
  const bool schur = solver.linear_solver_type == ceres::DENSE_SCHUR ||
                     solver.linear_solver_type == ceres::SPARSE_SCHUR ||
                     solver.linear_solver_type == ceres::ITERATIVE_SCHUR;
  if (schur && options.refine_points && options.refine_poses) solver.linear_solver_ordering = ordering;
  solver.max_num_iterations = options.max_iterations;
  solver.function_tolerance = options.function_tolerance;
  solver.gradient_tolerance = options.gradient_tolerance;
  solver.parameter_tolerance = options.parameter_tolerance;
  solver.num_threads = options.num_threads;
  solver.logging_type = ceres::SILENT;
  solver.minimizer_progress_to_stdout = false;
  return solver;
}

// The blocks the covariance keeps besides the poses: planes, projector maps and lens,
// relief nodes; the variable ones, in a fixed order.
std::vector<double*> OtherKeptBlocks(const ceres::Problem& problem, Parameters& params) {
  std::vector<double*> blocks;
  const auto keep = [&](double* block) {
    if (problem.HasParameterBlock(block) && !problem.IsParameterBlockConstant(block)) blocks.push_back(block);
  };
  for (int k = 0; k < 1 + static_cast<int>(params.more_planes.rows()); ++k) keep(params.Plane(k));
  for (int k = 0; k < static_cast<int>(params.map_valid.size()); ++k) {
    if (params.map_valid[k]) keep(params.Map(k));
  }
  keep(params.lens.data());
  keep(params.apex.data());
  for (int node = 0; node < params.relief_grid.size(); ++node) keep(params.ReliefNode(node));
  return blocks;
}

// The map from a pose block's tangent to [dtheta, dt] in the caller's frame.
Eigen::MatrixXd PoseTangentToCaller(const ceres::Problem& problem, const double* pose, const FrameChange& change) {
  const Eigen::Vector3d w = Eigen::Map<const Eigen::Vector3d>(pose);
  Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
  const Eigen::Matrix3d J_left = LeftJacobian(w);
  A.topLeftCorner<3, 3>() = J_left;
  A.bottomLeftCorner<3, 3>() = -Skew(RotationFromAngleAxis(w) * change.t) * J_left;
  A.bottomRightCorner<3, 3>().setIdentity();
  const ceres::Manifold* manifold = problem.GetManifold(pose);
  if (manifold == nullptr) return A;
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> plus(6, manifold->TangentSize());
  manifold->PlusJacobian(pose, plus.data());
  return A * plus;
}

// The lenses of Data::lens_block as considered parameters of the reduced system: an
// observation's residual block depends on its camera's lens block.
ConsideredParameters ConsideredLenses(const Data& data, const std::vector<ceres::ResidualBlockId>& observation_blocks) {
  auto observation_of = std::make_shared<std::unordered_map<ceres::ResidualBlockId, int>>();
  for (size_t i = 0; i < observation_blocks.size(); ++i) observation_of->emplace(observation_blocks[i], static_cast<int>(i));
  ConsideredParameters considered;
  considered.columns = kLensBlockSize * (data.lens_block.maxCoeff() + 1);
  considered.jacobian = [&data, observation_of](ceres::ResidualBlockId id, Eigen::MatrixXd* jacobian) {
    const auto it = observation_of->find(id);
    const int block = it == observation_of->end() ? -1 : data.lens_block(data.camera_index(it->second));
    if (block < 0) {
      jacobian->resize(0, 0);
      return 0;
    }
    *jacobian = Eigen::Map<const Eigen::Matrix<double, 2, kLensBlockSize, Eigen::RowMajor>>(
        data.lens_jacobians.row(it->second).data());
    return kLensBlockSize * block;
  };
  return considered;
}

// Nodes along each image axis of a camera's shared error field (Options::
// shared_error_field): 3 x 3 over the box of its observations.
constexpr int kFieldNodes = 3;

// Per camera, the box of its observed pixels: [u_min, v_min, u_max, v_max].
std::vector<Eigen::Vector4d> ObservedBoxes(const Data& data) {
  std::vector<Eigen::Vector4d> boxes(data.intrinsics.size(), Eigen::Vector4d(INFINITY, INFINITY, -INFINITY, -INFINITY));
  for (int i = 0; i < data.camera_index.size(); ++i) {
    Eigen::Vector4d& box = boxes[data.camera_index(i)];
    const Eigen::Vector2d uv = data.observed.row(i).transpose();
    box.head<2>() = box.head<2>().cwiseMin(uv);
    box.tail<2>() = box.tail<2>().cwiseMax(uv);
  }
  return boxes;
}

// The bilinear weights of the field's nodes at pixel uv of a camera's box, node (i, j)
// at index j * kFieldNodes + i.
Eigen::Matrix<double, kFieldNodes * kFieldNodes, 1> FieldWeights(const Eigen::Vector4d& box, const Eigen::Vector2d& uv) {
  Eigen::Matrix<double, kFieldNodes * kFieldNodes, 1> weights = Eigen::Matrix<double, kFieldNodes * kFieldNodes, 1>::Zero();
  double cell[2];
  int first[2];
  for (int axis = 0; axis < 2; ++axis) {
    const double extent = box(axis + 2) - box(axis);
    const double x = extent > 0.0 ? std::clamp((uv(axis) - box(axis)) / extent, 0.0, 1.0) * (kFieldNodes - 1) : 0.0;
    first[axis] = std::min(static_cast<int>(x), kFieldNodes - 2);
    cell[axis] = x - first[axis];
  }
  for (int dj = 0; dj < 2; ++dj) {
    for (int di = 0; di < 2; ++di) {
      weights((first[1] + dj) * kFieldNodes + first[0] + di) =
          (di ? cell[0] : 1.0 - cell[0]) * (dj ? cell[1] : 1.0 - cell[1]);
    }
  }
  return weights;
}

// The cameras' shared errors as considered parameters: per camera two columns, the
// shift along u and v that every observation of the camera takes whole
// (Options::shared_error_shift), and with `field` two per node of its shared error
// field, bilinear between the nodes (Options::shared_error_field).
ConsideredParameters ConsideredSharedErrors(const Data& data, const std::vector<ceres::ResidualBlockId>& observation_blocks,
                                            bool field) {
  auto observation_of = std::make_shared<std::unordered_map<ceres::ResidualBlockId, int>>();
  for (size_t i = 0; i < observation_blocks.size(); ++i) observation_of->emplace(observation_blocks[i], static_cast<int>(i));
  const int per_camera = 2 + (field ? 2 * kFieldNodes * kFieldNodes : 0);
  auto boxes = std::make_shared<std::vector<Eigen::Vector4d>>(ObservedBoxes(data));
  ConsideredParameters considered;
  considered.columns = per_camera * static_cast<int>(data.intrinsics.size());
  considered.jacobian = [observation_of, boxes, per_camera, &data](ceres::ResidualBlockId id, Eigen::MatrixXd* jacobian) {
    const auto it = observation_of->find(id);
    if (it == observation_of->end()) {
      jacobian->resize(0, 0);
      return 0;
    }
    const int camera = data.camera_index(it->second);
    jacobian->setZero(2, per_camera);
    jacobian->leftCols<2>().setIdentity();
    if (per_camera > 2) {
      const auto weights = FieldWeights((*boxes)[camera], data.observed.row(it->second).transpose());
      for (int node = 0; node < weights.size(); ++node) {
        jacobian->block<2, 2>(0, 2 + 2 * node) = weights(node) * Eigen::Matrix2d::Identity();
      }
    }
    return per_camera * camera;
  };
  return considered;
}

struct PoseCovariance {
  Eigen::MatrixXd joint;             // see Result::pose_covariance
  Eigen::MatrixXd sensitivity;  // d poses / d considered parameters (Result::lens_sensitivity's form), given some
};

// The joint covariance of every pose, [dtheta, dt] per camera in the caller's frame
// (see Result::pose_covariance), from the reduced camera system; with `lenses`, also
// the poses' sensitivity to them.
PoseCovariance JointPoseCovariance(ceres::Problem* problem, Parameters& params, const Gauge& gauge,
                                   const FrameChange& change, const ConsideredParameters* lenses) {
  const int num_cameras = static_cast<int>(params.poses.rows());
  if (gauge.scale_camera >= 0) {
    // The padded manifold used for speed has an inert direction; covariance needs the exact one.
    problem->SetManifold(params.poses.row(gauge.scale_camera).data(),
                         ScaleGaugeManifold(params, gauge.scale_camera).release());
  }
  std::vector<double*> points, kept;
  for (int p = 0; p < static_cast<int>(params.points.rows()); ++p) {
    if (!problem->IsParameterBlockConstant(params.PointBlock(p))) points.push_back(params.PointBlock(p));
  }
  std::vector<int> pose_column(num_cameras, -1);
  int columns = 0;
  for (int c = 0; c < num_cameras; ++c) {
    double* pose = params.poses.row(c).data();
    if (problem->IsParameterBlockConstant(pose)) continue;
    kept.push_back(pose);
    pose_column[c] = columns;
    columns += problem->ParameterBlockTangentSize(pose);
  }
  const std::vector<double*> others = OtherKeptBlocks(*problem, params);
  kept.insert(kept.end(), others.begin(), others.end());
  ReducedSolution reduced;
  if (lenses != nullptr) {
    reduced = ReducedCovarianceWithSensitivity(problem, points, kept, *lenses);
  } else {
    reduced.covariance = ReducedCovariance(problem, points, kept);
  }
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(6 * num_cameras, columns);
  for (int c = 0; c < num_cameras; ++c) {
    if (pose_column[c] < 0) continue;
    const Eigen::MatrixXd map = PoseTangentToCaller(*problem, params.poses.row(c).data(), change);
    M.block(6 * c, pose_column[c], 6, map.cols()) = map;
  }
  PoseCovariance out;
  const Eigen::MatrixXd joint = M * reduced.covariance.topLeftCorner(columns, columns) * M.transpose();
  out.joint = 0.5 * (joint + joint.transpose());
  if (lenses != nullptr) out.sensitivity = M * reduced.sensitivity.topRows(columns);
  return out;
}

// The poses' covariance with every camera's shared errors propagated into it, for
// residuals of unit variance: a camera weighed w (the reference noise over its own) has
// a shift of variance (shift / w)^2 per axis in those units, and each node of its field
// one of (field / w)^2.
Eigen::MatrixXd WithSharedErrors(ceres::Problem* problem, const Data& data, Parameters& params, const Gauge& gauge,
                                 const FrameChange& change, const std::vector<ceres::ResidualBlockId>& observation_blocks,
                                 double shift, double field) {
  const ConsideredParameters shared = ConsideredSharedErrors(data, observation_blocks, field > 0.0);
  const PoseCovariance given = JointPoseCovariance(problem, params, gauge, change, &shared);
  const int cameras = static_cast<int>(data.intrinsics.size());
  const int per_camera = shared.columns / std::max(cameras, 1);
  Eigen::VectorXd variance(shared.columns);
  for (int c = 0; c < cameras; ++c) {
    const double w = CameraWeight(data, c);
    variance.segment(per_camera * c, per_camera).setConstant(field * field / (w * w));
    variance.segment<2>(per_camera * c).setConstant(shift * shift / (w * w));
  }
  const Eigen::MatrixXd from_shared = given.sensitivity * variance.asDiagonal() * given.sensitivity.transpose();
  return given.joint + 0.5 * (from_shared + from_shared.transpose());
}

const char* ModelName(Model model) { return model == Model::kFree ? "free" : "coplanar"; }

}  // namespace

std::unique_ptr<ceres::LossFunction> MakeLoss(Loss loss, double scale_px) {
  switch (loss) {
    case Loss::kHuber: return std::make_unique<ceres::HuberLoss>(scale_px);
    case Loss::kCauchy: return std::make_unique<ceres::CauchyLoss>(scale_px);
    case Loss::kNone: break;
  }
  return nullptr;
}

void Options::Check() const {
  limits::RequireInRange(min_projector_points, 4, limits::kMaxPoints, "options: min_projector_points");
  Require(loss_scale_px > 0.0 && std::isfinite(loss_scale_px),
          "options: loss scale must be a positive number of pixels, got " + Str(loss_scale_px));
  limits::RequireInRange(max_iterations, 0, limits::kMaxIterations, "options: max_iterations");
  Require(function_tolerance >= 0.0 && gradient_tolerance >= 0.0 && parameter_tolerance >= 0.0 &&
              std::isfinite(function_tolerance + gradient_tolerance + parameter_tolerance),
          "options: tolerances must be finite and >= 0");
  limits::RequireInRange(num_threads, 1, limits::kMaxThreads, "options: num_threads");
  Require(refine_poses || refine_points, "options: nothing to refine (refine_poses and refine_points both off)");
  Require(!compute_covariance || refine_poses, "options: covariance needs refine_poses");
  Require(error_correlation >= 0.0 && error_correlation <= 1.0,
          "options: error_correlation must be in [0, 1], got " + Str(error_correlation));
  Require(shared_error_shift >= 0.0 && shared_error_shift <= 100.0,
          "options: shared_error_shift must be in [0, 100], got " + Str(shared_error_shift));
  Require(shared_error_field >= 0.0 && shared_error_field <= 100.0,
          "options: shared_error_field must be in [0, 100], got " + Str(shared_error_field));
  limits::RequireInRange(relief_cells, 1, kMaxReliefCells, "options: relief_cells");
}

namespace {

// The considered lenses: a block index per camera (-1: none), blocks numbered 0..L-1
// without gaps, and a finite 2 x 8 derivative per observation.
void ValidateLenses(const Data& data, int num_cameras) {
  if (data.lens_block.size() == 0 && data.lens_jacobians.rows() == 0) return;
  Require(data.lens_block.size() == num_cameras,
          "lens blocks: " + Str(int(data.lens_block.size())) + " entries for " + Str(num_cameras) + " cameras");
  Require(data.lens_jacobians.rows() == data.camera_index.size(),
          "lens Jacobians: " + Str(int(data.lens_jacobians.rows())) + " rows for " + Str(int(data.camera_index.size())) +
              " observations");
  Require(data.lens_jacobians.allFinite(), "lens Jacobians: non-finite value");
  std::vector<int> cameras_of_block(num_cameras, 0);
  for (int c = 0; c < num_cameras; ++c) {
    const int block = data.lens_block(c);
    Require(block >= -1 && block < num_cameras, "lens blocks: camera " + Str(c) + " has block " + Str(block));
    if (block >= 0) ++cameras_of_block[block];
  }
  const int blocks = data.lens_block.maxCoeff() + 1;
  for (int b = 0; b < blocks; ++b) {
    Require(cameras_of_block[b] == 1, "lens blocks: block " + Str(b) + " belongs to " + Str(cameras_of_block[b]) +
                                          " cameras (one each, numbered without gaps)");
  }
}

}  // namespace

void ValidateData(const Data& data, const Options& options) {
  options.Check();
  const int num_obs = static_cast<int>(data.camera_index.size());
  const int num_cameras = static_cast<int>(data.poses.rows());
  const int num_points = static_cast<int>(data.points.rows());
  Require(num_obs > 0, "empty problem: no observations");
  Require(num_cameras > 0, "empty problem: no cameras");
  Require(num_points > 0, "empty problem: no points");
  Require(data.point_index.size() == num_obs,
          "observations: " + Str(num_obs) + " camera indices but " + Str(int(data.point_index.size())) +
              " point indices");
  Require(data.observed.rows() == num_obs,
          "observations: " + Str(num_obs) + " camera indices but " + Str(int(data.observed.rows())) + " pixels");
  Require(static_cast<int>(data.intrinsics.size()) == num_cameras,
          "intrinsics: " + Str(int(data.intrinsics.size())) + " cameras but " + Str(num_cameras) + " poses");
  Require(data.poses.allFinite(), "poses: non-finite value");
  Require(data.points.allFinite(), "points: non-finite value");
  Require(data.observed.allFinite(), "observations: non-finite pixel");
  for (int c = 0; c < num_cameras; ++c) {
    const Intrinsics& K = data.intrinsics[c];
    Require(std::isfinite(K.fx) && std::isfinite(K.fy) && std::isfinite(K.cx) && std::isfinite(K.cy) &&
                std::isfinite(K.skew),
            "intrinsics of camera " + Str(c) + ": non-finite value");
    Require(K.fx > 0.0 && K.fy > 0.0, "intrinsics of camera " + Str(c) + ": focal lengths must be positive");
  }
  std::vector<int> camera_count(num_cameras, 0), point_count(num_points, 0);
  // Messages are built only on failure: these loops run over every observation.
  for (int i = 0; i < num_obs; ++i) {
    const int c = data.camera_index(i);
    const int p = data.point_index(i);
    if (c < 0 || c >= num_cameras) {
      Fail("observation " + Str(i) + ": camera index " + Str(c) + " out of range [0, " + Str(num_cameras) + ")");
    }
    if (p < 0 || p >= num_points) {
      Fail("observation " + Str(i) + ": point index " + Str(p) + " out of range [0, " + Str(num_points) + ")");
    }
    ++camera_count[c];
    ++point_count[p];
  }
  for (int c = 0; c < num_cameras; ++c) {
    if (camera_count[c] == 0) Fail("camera " + Str(c) + " has no observation");
  }
  for (int p = 0; p < num_points; ++p) {
    if (point_count[p] == 0) Fail("point " + Str(p) + " has no observation");
  }
  if (options.model == Model::kCoplanar) {
    Require(data.plane.allFinite(), "plane: non-finite value");
    Require(data.plane.head<3>().norm() > 1e-12, "plane: the normal is zero");
    Require(data.more_planes.allFinite(), "more planes: non-finite value");
    for (int k = 0; k < data.more_planes.rows(); ++k) {
      Require(data.more_planes.row(k).head<3>().norm() > 1e-12, "plane " + Str(k + 1) + ": the normal is zero");
    }
    Require(data.point_plane.size() == 0 || data.point_plane.size() == num_points,
            "point planes: " + Str(int(data.point_plane.size())) + " entries for " + Str(num_points) + " points");
    const int num_planes = 1 + static_cast<int>(data.more_planes.rows());
    for (int p = 0; p < data.point_plane.size(); ++p) {
      if (data.point_plane(p) < -1 || data.point_plane(p) >= num_planes) {
        Fail("point " + Str(p) + ": plane " + Str(data.point_plane(p)) + " out of range [-1, " + Str(num_planes) + ")");
      }
    }
  }
  Require(data.camera_weights.size() == 0 || data.camera_weights.size() == num_cameras,
          "camera weights: " + Str(int(data.camera_weights.size())) + " entries for " + Str(num_cameras) + " cameras");
  for (int c = 0; c < data.camera_weights.size(); ++c) {
    Require(std::isfinite(data.camera_weights(c)) && data.camera_weights(c) > 0.0,
            "camera weights: camera " + Str(c) + " needs a positive finite weight");
  }
  Require(data.projector.rows() == 0 || data.projector.rows() == num_points,
          "projector: " + Str(int(data.projector.rows())) + " pixels for " + Str(num_points) + " points");
  for (int p = 0; p < data.projector.rows(); ++p) {
    const bool known = data.projector.row(p).allFinite();
    Require(known || data.projector.row(p).array().isNaN().all(),
            "projector: point " + Str(p) + " needs a finite pixel or NaN in both coordinates");
  }
  Require(data.projector_lens.allFinite() && std::isfinite(data.projector_weight) && data.projector_weight >= 0.0,
          "projector: lens and weight must be finite, the weight >= 0");
  Require(data.projector_point_weights.size() == 0 ||
              (data.projector_point_weights.size() == num_points && data.projector_point_weights.allFinite() &&
               (data.projector_point_weights.array() > 0.0).all()),
          "projector: one finite positive weight factor per point, or none");
  Require(std::isfinite(data.relief_weight) && data.relief_weight >= 0.0, "relief: the weight must be finite and >= 0");
  Require(std::isfinite(data.apex_prior_px) && data.apex_prior_px >= 0.0,
          "projector apex: the prior's noise must be finite and >= 0");
  ValidateLenses(data, num_cameras);
  Require(options.gauge_camera >= 0 && options.gauge_camera < num_cameras,
          "options: gauge camera " + Str(options.gauge_camera) + " out of range [0, " + Str(num_cameras) + ")");
  Require(options.scale_camera >= -1 && options.scale_camera < num_cameras &&
              options.scale_camera != options.gauge_camera,
          "options: scale camera " + Str(options.scale_camera) + " must be another camera in range");
  const PixelMatrix residuals = ComputeResiduals(data);
  for (int i = 0; i < num_obs; ++i) {
    if (!std::isfinite(residuals(i, 0))) {
      Fail("observation " + Str(i) + ": point " + Str(data.point_index(i)) + " is behind camera " +
           Str(data.camera_index(i)));
    }
  }
}

PixelMatrix ComputeResiduals(const Data& data) {
  const int num_obs = static_cast<int>(data.camera_index.size());
  PixelMatrix residuals(num_obs, 2);
  std::vector<const double*> pose_blocks;
  for (int c = 0; c < data.poses.rows(); ++c) pose_blocks.push_back(data.poses.row(c).data());
  const RotationCache rotations(pose_blocks);  // one rotation per camera, not per observation
  for (int i = 0; i < num_obs; ++i) {
    const int camera = data.camera_index(i);
    const FreePointReprojectionCost cost(data.intrinsics[camera], data.observed.row(i).transpose(),
                                         rotations.Entry(camera));
    const double* blocks[2] = {data.poses.row(data.camera_index(i)).data(), data.points.row(data.point_index(i)).data()};
    double r[2];
    if (cost.Evaluate(blocks, r, nullptr)) {
      residuals.row(i) << r[0], r[1];
    } else {
      residuals.row(i).setConstant(std::numeric_limits<double>::quiet_NaN());
    }
  }
  return residuals;
}

bool ProjectorPoint(const ProjectorSurface& surface, const Eigen::Vector2d& lens, const Eigen::Vector2d& normalised,
                    Eigen::Vector3d* X) {
  if (!surface.valid) return false;
  Eigen::Vector2d ab;
  if (!InvertSurfaceMap(surface.map, UndistortProjector(normalised, lens), &ab)) return false;
  *X = surface.world_from_plane * ab.homogeneous();
  return X->allFinite();
}

CostFactory AnalyticCosts() {
  return [](Model model, const Intrinsics& K, const Eigen::Vector2d& observed,
            const CachedRotation* rotation) -> ceres::CostFunction* {
    if (model == Model::kFree) return new FreePointReprojectionCost(K, observed, rotation);
    return new PlanePointReprojectionCost(K, observed, rotation);
  };
}

Result BundleAdjust(const Data& data, const Options& options) { return BundleAdjust(data, options, AnalyticCosts()); }

Result BundleAdjust(const Data& data, const Options& requested, const CostFactory& make_cost) {
  ValidateData(data, requested);
  // With points held fixed there is no plane to refine: both models are the same.
  Options options = requested;
  if (!options.refine_points) options.model = Model::kFree;
  const int num_cameras = static_cast<int>(data.poses.rows());

  Gauge gauge;
  gauge.camera = options.gauge_camera;
  gauge.fixed = options.refine_poses && options.refine_points;
  FrameChange change;
  change.R = PoseRotation(data.poses, gauge.camera);
  change.t = data.poses.row(gauge.camera).tail<3>().transpose();
  const Data gauge_data = ToGaugeFrame(data, change);
  if (gauge.fixed && options.model == Model::kFree) {
    if (num_cameras < 2) throw std::invalid_argument("FREE bundle adjustment needs at least 2 cameras");
    gauge.scale_camera =
        options.scale_camera >= 0 ? options.scale_camera : FarthestCamera(gauge_data.poses, gauge.camera);
    Require(gauge.scale_camera >= 0 && gauge_data.poses.row(gauge.scale_camera).tail<3>().norm() > 1e-12,
            "scale gauge: the scale camera's centre coincides with the gauge camera's");
  }
  if (options.model == Model::kCoplanar) {
    Require(std::abs(gauge_data.plane(3)) > 1e-12 * gauge_data.plane.head<3>().norm(),
            "plane: passes through the gauge camera's centre");
  }

  Parameters params = InitialParameters(gauge_data, options);
  const std::unique_ptr<ceres::LossFunction> loss = MakeLoss(options.loss, options.loss_scale_px);
  std::unique_ptr<RotationCache> rotations;
  if (options.cache_rotations) {
    std::vector<const double*> pose_blocks;
    for (int c = 0; c < num_cameras; ++c) pose_blocks.push_back(params.poses.row(c).data());
    rotations = std::make_unique<RotationCache>(pose_blocks);
  }
  ceres::Problem::Options problem_options;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_options.enable_fast_removal = false;
  problem_options.disable_all_safety_checks = true;  // ValidateData has run
  problem_options.evaluation_callback = rotations.get();
  ceres::Problem problem(problem_options);
  auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
  const bool shared_errors = options.compute_covariance && options.error_correlation > 0.0;
  GroupLosses losses = MakeGroupLosses(data, loss.get(), shared_errors);
  std::vector<ceres::ResidualBlockId> observation_blocks;
  const int projector_terms =
      BuildProblem(gauge_data, options, gauge, params, make_cost, rotations.get(), losses, &problem, ordering.get(),
                   &observation_blocks);

  ceres::Solver::Summary summary;
  const auto start = std::chrono::steady_clock::now();
  ceres::Solve(SolverOptions(options, num_cameras, ordering), &problem, &summary);
  const auto stop = std::chrono::steady_clock::now();

  Result result;
  result.initial_cost = summary.initial_cost;
  result.final_cost = summary.final_cost;
  result.iterations = static_cast<int>(summary.iterations.size()) - 1;
  result.termination = ceres::TerminationTypeToString(summary.termination_type);
  result.usable = summary.IsSolutionUsable();
  result.solve_time_s = std::chrono::duration<double>(stop - start).count();
  result.gauge_camera = gauge.fixed ? gauge.camera : -1;
  result.scale_camera = gauge.scale_camera;
  result.report = options.full_report ? summary.FullReport() : summary.BriefReport();
  result.report += std::string("\nmodel: ") + ModelName(options.model);

  if (rotations) rotations->Refresh();  // the last evaluation may have been a rejected step
  if (options.compute_covariance && result.usable) {
    const auto covariance_start = std::chrono::steady_clock::now();
    const bool lenses = data.lens_block.size() > 0 && data.lens_block.maxCoeff() >= 0;
    const ConsideredParameters considered = lenses ? ConsideredLenses(data, observation_blocks) : ConsideredParameters();
    try {
      // The lenses move the poses as the solve weighs the residuals: their sensitivity
      // is taken before the covariance discounts shared errors.
      PoseCovariance with_lenses;
      if (lenses) {
        with_lenses = JointPoseCovariance(&problem, params, gauge, change, &considered);
        result.lens_sensitivity = with_lenses.sensitivity;
      }
      const bool shifts = options.shared_error_shift > 0.0 || options.shared_error_field > 0.0;
      if (shared_errors) DiscountSharedErrors(data, options.error_correlation, projector_terms, !shifts, &losses);
      if (shifts) {
        result.pose_covariance = WithSharedErrors(&problem, data, params, gauge, change, observation_blocks,
                                                  options.shared_error_shift, options.shared_error_field);
      } else {
        result.pose_covariance = lenses && !shared_errors ? with_lenses.joint
                                                          : JointPoseCovariance(&problem, params, gauge, change, nullptr).joint;
      }
      for (int c = 0; c < num_cameras; ++c) result.pose_covariances.push_back(result.pose_covariance.block<6, 6>(6 * c, 6 * c));
    } catch (const std::runtime_error& error) {
      result.covariance_failure = error.what();  // the solution stands without it
    }
    result.covariance_time_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - covariance_start).count();
  }
  if (options.model == Model::kCoplanar) CopyProjectorOut(gauge_data, params, change, &result);
  if (params.HasRelief()) {
    result.relief_nodes = params.relief_grid.size();
    double sum = 0.0;
    for (int node = 0; node < result.relief_nodes; ++node) sum += *params.ReliefNode(node) * *params.ReliefNode(node);
    result.relief_rms = std::sqrt(sum / result.relief_nodes);
    result.relief_prior_cost = 0.5 * data.relief_weight * data.relief_weight * sum;
    if (params.has_apex) {
      result.relief_prior_cost += 0.5 * params.apex_weights.cwiseProduct(params.apex - params.apex_mean).squaredNorm();
    }
  }
  result.poses = params.poses;
  result.plane = params.plane;
  result.more_planes = params.more_planes;
  CopyPointsOut(params, &result.points);
  FromGaugeFrame(change, &result.poses, &result.points, &result.plane, &result.more_planes);
  // The gauge camera did not move: return its pose bit for bit.
  if (gauge.fixed || !options.refine_poses) {
    result.poses.row(gauge.camera) = data.poses.row(gauge.camera);
  }
  if (!options.refine_poses) result.poses = data.poses;
  if (!options.refine_points) result.points = data.points;
  if (options.model == Model::kFree) {
    result.plane = data.plane;
    result.more_planes = data.more_planes;
  }
  // Keep the caller's orientation of the normals.
  if (options.model == Model::kCoplanar && result.plane.head<3>().dot(data.plane.head<3>()) < 0.0) {
    result.plane = -result.plane;
  }
  for (int k = 0; k < result.more_planes.rows() && options.model == Model::kCoplanar; ++k) {
    if (result.more_planes.row(k).head<3>().dot(data.more_planes.row(k).head<3>()) < 0.0) {
      result.more_planes.row(k) = -result.more_planes.row(k);
    }
  }

  Data final_data = data;
  final_data.poses = result.poses;
  final_data.points = result.points;
  result.residuals = ComputeResiduals(final_data);
  return result;
}

}  // namespace calibproj::ba
