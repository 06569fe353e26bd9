#pragma once
// Bundle adjustment of camera poses and points (FREE) or of poses, one plane and
// points on it (COPLANAR), with fixed pinhole intrinsics and undistorted observations.
//
// Gauge. The world frame and scale are not observable; both are fixed so that the
// problem is well posed:
//  - the gauge camera's pose is held constant (6 dof);
//  - COPLANAR: the distance from the gauge camera's centre to the plane is held
//    constant (1 dof);
//  - FREE: the distance between the gauge camera's centre and the scale camera's
//    centre is held constant (1 dof; the scale camera is by default the one
//    farthest from the gauge camera).
// Internally the problem is solved in the gauge camera's frame, where these become
// a constant block, the plane offset and the length of a translation; results are
// returned in the caller's frame.

#include <Eigen/Core>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "calibproj/ba/camera.h"
#include "calibproj/ba/projector_cost.h"

namespace ceres {
class CostFunction;
class LossFunction;
}  // namespace ceres

namespace calibproj::ba {

enum class Model { kFree, kCoplanar };
enum class Loss { kNone, kHuber, kCauchy };
enum class LinearSolver { kAuto, kDenseSchur, kSparseSchur, kIterativeSchur, kDenseQr, kSparseNormalCholesky };

using PoseMatrix = Eigen::Matrix<double, Eigen::Dynamic, 6, Eigen::RowMajor>;
using PointMatrix = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
using PixelMatrix = Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>;
using Matrix6d = Eigen::Matrix<double, 6, 6, Eigen::RowMajor>;

struct Options {
  Model model = Model::kFree;
  Loss loss = Loss::kNone;
  double loss_scale_px = 1.0;  // Huber/Cauchy scale, in pixels
  int max_iterations = 100;
  double function_tolerance = 1e-12;
  double gradient_tolerance = 1e-14;
  double parameter_tolerance = 1e-12;
  int num_threads = 1;
  LinearSolver linear_solver = LinearSolver::kAuto;
  bool refine_poses = true;
  bool refine_points = true;  // points and, in COPLANAR, the plane
  int gauge_camera = 0;
  int scale_camera = -1;      // FREE only; -1 picks the camera farthest from the gauge camera
  bool compute_covariance = false;
  bool full_report = false;
  bool cache_rotations = true;  // one rotation per camera and evaluation (rotation_cache.h)
  // COPLANAR with a projector (Data::projector): a plane gets a projector map when this
  // many of its points have a projector pixel.
  int min_projector_points = 12;
  // With compute_covariance: the correlation of one camera's residuals (a share of each
  // error common to all of them: the lens model, blur, a floor's texture), and of the
  // projector's. The covariance counts a group of N residuals as N / (1 + (N - 1) *
  // error_correlation) independent ones; the solution does not depend on it.
  double error_correlation = 0.0;
  // With compute_covariance: each camera's shared errors as a shift that all its
  // observations take, of standard deviation shared_error_shift times the camera's noise
  // along each image axis (a bias of its detections, its principal point, a timing
  // offset), instead of error_correlation's discount. The shifts are considered
  // parameters: their effect on every pose is propagated into the covariance, so that a
  // camera's shift moves its own pose and what it places, not the local shape of the
  // patch it measures for a zoomed camera. error_correlation then discounts the
  // projector's residuals only (and the registration the refined lenses' covariance).
  // 0: every residual group discounted by error_correlation.
  double shared_error_shift = 0.0;
  // Each camera's shared errors also as a smooth field over its image: independent
  // shifts at the nodes of a 3 x 3 grid over the box of its observations, bilinear
  // between them, of this many times its noise along each axis, propagated into the
  // covariance as the shift is. A far camera's detection errors that vary across its
  // view tilt the floor's relief under a zoomed camera's patch, which the uniform shift
  // does not. 0: off.
  double shared_error_field = 0.0;
  // COPLANAR with Data::relief_weight > 0: cells of the main plane's relief grid across
  // the larger extent of its points (relief_cost.h), at most kMaxReliefCells.
  int relief_cells = 24;
  // The relief's height between its nodes: a cubic B-spline (true) or bilinear.
  bool relief_cubic = false;

  // Throws std::invalid_argument naming the first inconsistent option.
  void Check() const;
};

using PlaneMatrix = Eigen::Matrix<double, Eigen::Dynamic, 4, Eigen::RowMajor>;
constexpr int kLensBlockSize = 8;
using LensJacobianMatrix = Eigen::Matrix<double, Eigen::Dynamic, 2 * kLensBlockSize, Eigen::RowMajor>;

struct Data {
  Eigen::VectorXi camera_index;   // per observation
  Eigen::VectorXi point_index;    // per observation
  PixelMatrix observed;           // per observation, undistorted pixels
  std::vector<Intrinsics> intrinsics;  // per camera
  PoseMatrix poses;               // per camera: cam_from_world [w, t]
  PointMatrix points;             // per point, world coordinates
  Eigen::Vector4d plane = Eigen::Vector4d(0, 0, 1, 0);  // COPLANAR: [n, d], n . X = d
  // COPLANAR made piecewise planar (a table left in the projection): more planes, and
  // per point the plane it lies on, 0 for `plane`, k >= 1 for row k - 1 of
  // `more_planes`, -1 for a point off every plane (a free 3D point). Empty: every
  // point on `plane`. Only `plane` carries the scale gauge; the others move freely.
  PlaneMatrix more_planes;
  Eigen::VectorXi point_plane;
  // Per camera, the factor its reprojection residuals are multiplied by in the cost
  // (the reference noise over the camera's own); empty: 1 for every camera.
  Eigen::VectorXd camera_weights;
  // COPLANAR: the projector (projector_cost.h). Per point its normalised projector
  // pixel, NaN for a point the projector did not draw; empty: no projector term. The
  // term joins a plane's points once min_projector_points of them have a pixel.
  PixelMatrix projector;
  Eigen::Vector2d projector_lens = Eigen::Vector2d::Zero();
  double projector_weight = 0.0;  // see ProjectorSurfaceCost; <= 0: no projector term
  // Per point, the factor its projector term's weight is multiplied by (its group's
  // noise against the projector's reference); empty: 1 for every point.
  Eigen::VectorXd projector_point_weights;
  // COPLANAR: the main plane's points may leave it by a smooth relief (relief_cost.h)
  // whose nodes have a prior of weight relief_weight = the reference noise (px) over the
  // expected root mean square height (world units); <= 0: the plane is flat.
  double relief_weight = 0.0;
  // COPLANAR with a relief and a projector term: the reference noise (px) that the prior
  // of the projector's apex (relief_cost.h) is weighed in; the apex is then refined, so
  // that the projector sees a raised centre along its ray. <= 0: it sees every centre
  // of the main plane at its foot on the plane.
  double apex_prior_px = 0.0;
  // With compute_covariance: lenses the solve holds but whose own uncertainty is known
  // elsewhere (intrinsics refined by the self-calibration), whose effect on the poses the
  // result gives (Result::lens_sensitivity). Per camera the index of its lens block (-1:
  // none), and per observation the derivative of its residual by its camera's lens
  // block [f, cx, cy, k1, k2, p1, p2, k3] (selfcal/lens.h: ResidualByLens), 2 x 8
  // row-major. Both empty: no lens considered.
  Eigen::VectorXi lens_block;
  LensJacobianMatrix lens_jacobians;
};

constexpr int kMaxReliefCells = 32;

// Planes that can have a projector map (the main plane first; further ones have none).
constexpr int kMaxProjectorSurfaces = 16;

// A surface's projector map in the caller's frame: the world point of plane
// coordinates (a, b) is world_from_plane * [a, b, 1].
struct ProjectorSurface {
  bool valid = false;
  SurfaceMap map = SurfaceMap::Zero();
  Eigen::Matrix3d world_from_plane = Eigen::Matrix3d::Zero();
};

// The world point where the projector draws the normalised pixel on `surface`; false
// where the map is not valid or not defined.
bool ProjectorPoint(const ProjectorSurface& surface, const Eigen::Vector2d& lens, const Eigen::Vector2d& normalised,
                    Eigen::Vector3d* X);

struct Result {
  double initial_cost = 0.0;  // 0.5 * sum of squared (robustified) residuals
  double final_cost = 0.0;
  int iterations = 0;
  std::string termination;
  bool usable = false;
  double solve_time_s = 0.0;
  double covariance_time_s = 0.0;  // of the covariance, when requested
  int gauge_camera = -1;
  int scale_camera = -1;      // FREE with poses and points refined; -1 otherwise
  PoseMatrix poses;
  PointMatrix points;         // COPLANAR: on their plane (but the free ones), or on the main plane's relief
  Eigen::Vector4d plane = Eigen::Vector4d::Zero();
  PlaneMatrix more_planes;    // COPLANAR: the other planes, refined
  PixelMatrix residuals;      // per observation, projected minus observed, pixels
  // When requested: the joint covariance (6C x 6C, cross terms included) of every
  // camera's [dtheta, dt] with R = Exp(dtheta) R_hat, t = t_hat + dt, in the caller's
  // frame, for residuals of unit variance (each camera's weight applied); the gauge
  // camera's rows are zero. And its diagonal blocks, per camera.
  Eigen::MatrixXd pose_covariance;
  std::vector<Matrix6d> pose_covariances;
  // With Data::lens_block: d [dtheta, dt] / d lens (6C x 8L, lens block l in columns 8l
  // to 8l + 7), in the caller's frame; the gauge camera's rows are zero. The poses'
  // covariance from the lenses' is lens_sensitivity * Sigma_lens * lens_sensitivity^T.
  Eigen::MatrixXd lens_sensitivity;
  // Why the covariance was requested but not given (the poses not all determined: a
  // camera seeing too little); empty otherwise.
  std::string covariance_failure;
  // With a projector term: per plane (0 the main one) its map, the lens, per point the
  // projector residual G(a, b) - u in normalised projector units (NaN without a term),
  // and how many points had one.
  std::vector<ProjectorSurface> projector_surfaces;
  Eigen::Vector2d projector_lens = Eigen::Vector2d::Zero();
  PixelMatrix projector_residuals;
  int projector_terms = 0;
  // With a relief and Data::apex_prior_px: the projector's optical centre, in the
  // caller's frame, as the relief's parallax places it; NaN otherwise.
  Eigen::Vector3d projector_centre = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  // With a relief: root mean square of its node heights (world units), how many, and
  // the share of final_cost its prior holds (final_cost - relief_prior_cost is the
  // cost of the observations alone).
  double relief_rms = 0.0;
  int relief_nodes = 0;
  double relief_prior_cost = 0.0;
  std::string report;         // Ceres FullReport when requested, else BriefReport
};

// The Ceres robust loss of `loss` at `scale_px` pixels; null for Loss::kNone.
std::unique_ptr<ceres::LossFunction> MakeLoss(Loss loss, double scale_px);

// Throws std::invalid_argument with a message naming the problem: sizes that do not
// match, indices out of range, non-finite values, an empty problem, a camera or a
// point without observations, a point behind a camera that observes it.
void ValidateData(const Data& data, const Options& options);

// Validates, then solves. Never lets a Ceres CHECK see bad input.
Result BundleAdjust(const Data& data, const Options& options);

// The cost of one observation, owned by the caller's ceres::Problem. The product
// path uses the analytic costs of reprojection_cost.h; tools/bench swaps in
// automatic differentiation of the same residuals to measure the difference.
// `rotation` is the camera's cached rotation when Options::cache_rotations is on, else null.
struct CachedRotation;
using CostFactory = std::function<ceres::CostFunction*(Model model, const Intrinsics& K,
                                                       const Eigen::Vector2d& observed,
                                                       const CachedRotation* rotation)>;
Result BundleAdjust(const Data& data, const Options& options, const CostFactory& make_cost);
CostFactory AnalyticCosts();

// Residual of every observation (projected minus observed), NaN behind the camera.
PixelMatrix ComputeResiduals(const Data& data);

}  // namespace calibproj::ba
