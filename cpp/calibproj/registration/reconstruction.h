#pragma once
// Incremental registration of a camera network from point tracks (paper section 2.2).
//
// The Reconstruction holds the state (which cameras are registered, their poses,
// which points are reconstructed, the plane, which observations are inliers) and
// offers each step of the algorithm as a method. The order of the steps lives in
// Run() (incremental.h) and, step by step, in the Python driver: both call the same
// methods, so every algorithmic step exists once.

#include <Eigen/Core>
#include <opencv2/core/types.hpp>
#include <algorithm>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "calibproj/ba/bundle_adjuster.h"
#include "calibproj/geometry/triangulation.h"
#include "calibproj/registration/noise_model.h"
#include "calibproj/selfcal/lens.h"

namespace calibproj::registration {

struct Options {
  ba::Model model = ba::Model::kCoplanar;
  double homography_threshold_px = 3.0;  // initial pair RANSAC, in each camera's own pixels
  double pnp_threshold_px = 3.0;         // PnP RANSAC, in the new camera's pixels
  int ransac_max_iterations = 2000;
  double ransac_confidence = 0.9999;
  std::uint64_t seed = 0;
  int min_pair_points = 15;         // common points for the initial pair and the third camera
  int min_pnp_points = 6;           // 2D-3D correspondences to register a camera
  double min_triangulation_angle_deg = 1.0;  // FREE: new points need this much parallax
  double min_pair_parallax_deg = 2.0;        // initial pair: median parallax of its points
  double outlier_threshold_px = 1.0;    // observations above max(this, factor * sigma) are removed
  double outlier_sigma_factor = 3.0;    // 0 keeps the fixed threshold of the paper
  int max_refine_rounds = 10;
  int view_score_levels = 6;   // COLMAP default: rewards many points as well as their spread
  ba::Loss loss = ba::Loss::kNone;
  double loss_scale_px = 1.0;
  int num_threads = 1;
  int intermediate_ba_iterations = 25;  // after each new camera
  int final_ba_iterations = 100;
  // A camera whose rotation is known worse than this (1 sigma, from the final bundle
  // adjustment's covariance) is reported as weak.
  double weak_rotation_sigma_deg = 0.05;
  // COPLANAR: points off the main plane (a table, a cart left in the projection) are
  // triangulated; at the end, planes are found among them (RANSAC), up to `max_planes`
  // more, each with `min_plane_points` points within `plane_distance` (in units of the
  // first camera's height above the main plane) at least.
  int max_planes = 3;
  int min_plane_points = 30;
  double plane_distance = 0.004;
  // COPLANAR with projector pixels (SetProjector): every centre's plane coordinates are
  // tied to its projector pixel through its surface's map (ba/projector_cost.h), and a
  // camera can be registered on centres no other camera has placed (their points
  // predicted from the maps; min_projector_pnp_points of them suffice).
  bool use_projector = true;
  int min_projector_pnp_points = 4;
  // Each camera's centre noise and the projector maps' from the residuals (variance
  // components, noise_model.h), used as weights and for the covariance; off: one noise
  // for all cameras, the projector at projector_sigma_px.
  bool estimate_noise = true;
  double projector_sigma_px = 0.1;  // projector pixels, until estimated
  // The correlation of the projector's errors, and of one camera's centre errors with
  // shared_error_shift 0 (ba::Options::error_correlation): the covariance counts N of
  // them as N / (1 + (N - 1) * this) independent ones.
  double error_correlation = 0.005;
  // Each camera's shared errors as a shift of its centres instead, this many times its
  // noise (ba::Options::shared_error_shift); error_correlation then discounts the
  // projector's residuals and the refined lenses' covariance only. 0: off. 1 is what
  // rendered rooms with realistic effects show (README, "How accurate is it in
  // millimetres?").
  double shared_error_shift = 1.0;
  // Each camera's shared errors also as a smooth field over its image, this many times
  // its noise at each node of a 3 x 3 grid (ba::Options::shared_error_field). 0: off.
  // 0.75 is where the rendered rooms with a floor 6 mm uneven hold the zoomed camera
  // within 3 sigma (5.2 sigma without; README, "A floor that is not quite flat").
  double shared_error_field = 0.75;
  // COPLANAR: the expected root mean square height of the main plane's unevenness (a
  // real floor's), as a share of the extent of the centres on it (0.001: 3 mm over a
  // 3 m projection). Its points may leave the plane by a smooth relief with that prior
  // (ba/relief_cost.h); 0: an exactly flat plane.
  double floor_relief = 0.001;
  // COPLANAR with a relief: the relief grid's cells across the larger extent of the
  // main plane's centres.
  int relief_cells = 24;
  // The relief's height between its nodes: a cubic B-spline (smooth slope and
  // curvature across the cells' edges) or, off, bilinear (ba::Options::relief_cubic).
  // Off by default: each centre then depends on 16 nodes instead of 4, and the solver's
  // Schur elimination takes 2.5-4x as long (the refinement of the demo room on a floor
  // 6 mm uneven: 4.9 s against 2.0 s) for a zoomed camera 0-25 % nearer the truth on
  // the rendered rooms measured (README).
  bool relief_cubic = false;

  void Check() const;
};

struct Camera {
  ba::Intrinsics K;
  double width = 0.0, height = 0.0;
};

using LensCovariance = Eigen::Matrix<double, selfcal::kLensSize, selfcal::kLensSize>;

// A lens refined elsewhere (the self-calibration), with its covariance: the observations
// are undistorted with it, and the poses' covariance takes its uncertainty in.
struct LensUncertainty {
  double lens[selfcal::kLensSize] = {};  // [f, cx, cy, k1, k2, p1, p2, k3]
  selfcal::LensShape shape;
  LensCovariance covariance = LensCovariance::Zero();  // zero outside the refined entries
};

struct PairCandidate {
  int camera1 = -1, camera2 = -1;
  int score1 = 0, score2 = 0;  // view scores of the common points in each camera
  int common_points = 0;
  int connected_cameras = 0;  // size of the group of cameras connected to this pair
};

struct InitialPairResult {
  bool success = false;
  std::string reason;
  int homography_inliers = 0;
  double median_parallax_deg = 0.0;
  int solutions = 0;          // decompositions with the points in front of both cameras
  int third_camera = -1;      // camera used to pick between two solutions; -1 if refined both
  double normal_agreement = 0.0;  // cosine between the chosen normal and the third camera's
  int points = 0;
};

struct NextCameraCandidate {
  int camera = -1;
  int score = 0;
  int points = 0;  // observations of reconstructed points
};

struct RegisterResult {
  bool success = false;
  std::string reason;
  int correspondences = 0;
  int inliers = 0;
  double mean_error_px = 0.0;  // after refinement, over the inliers
};

struct AdjustResult {
  double initial_cost = 0.0, final_cost = 0.0;
  // final_cost of the observations alone (a relief's prior left out), and the noise
  // (px) one unit of weight stands for: 2 * observation_cost / reference_sigma_px^2 is
  // their chi-square.
  double observation_cost = 0.0;
  double reference_sigma_px = 1.0;
  int relief_nodes = 0;
  int iterations = 0;
  std::string termination;
  int cameras = 0, points = 0, observations = 0;
  double solve_time_s = 0.0;
  double covariance_time_s = 0.0;
};

// COPLANAR with a relief prior (Options::floor_relief): whether the main plane's relief
// explains the observations better than their noise and shared errors would, by the likelihood ratio of
// the relief against an exactly flat plane. A relief that is not detected is left out:
// on a flat floor it would only widen the zoomed camera's sigma, since that camera
// cannot tell the slope of the patch it sees from its own tilt.
struct ReliefTest {
  bool tested = false;
  bool detected = false;
  int nodes = 0;
  double gain_chi2 = 0.0;       // chi-square of the observations the relief takes off
  double threshold_chi2 = 0.0;  // kReliefSharedErrorFactor times the 99.9 % quantile of chi-square
                                // with `nodes` degrees of freedom
  bool parallax = false;        // the projector's apex is refined with the relief (kApexGainFactor)

  // One line for the log: the verdict and its figures ("" when not tested).
  std::string Describe() const;
};

struct RefineResult {
  int rounds = 0;
  int changed = 0;  // observations whose inlier status changed, over all rounds
  int removed = 0;  // inactive observations at the end
  int planes_found = 0;  // COPLANAR: planes found besides the main one (FindPlanes)
  ReliefTest relief;
  AdjustResult last;
  std::vector<double> thresholds;  // per camera, pixels
  double seconds = 0.0;             // wall time of the whole refinement
  double covariance_seconds = 0.0;  // of it, the covariance's
};

class Reconstruction {
 public:
  using PixelMatrix = ba::PixelMatrix;

  // Validates the inputs (std::invalid_argument naming the problem).
  Reconstruction(std::vector<Camera> cameras, int num_points, Eigen::VectorXi camera_index,
                 Eigen::VectorXi point_index, PixelMatrix observed, Options options);

  // Steps, in the order Run() calls them.
  std::vector<PairCandidate> RankInitialPairs() const;
  InitialPairResult Initialize(int camera1, int camera2);
  NextCameraCandidate ChooseNextCamera() const;
  RegisterResult RegisterCamera(int camera);
  int AddPoints(int camera);
  // `covariance`: also the pose covariance of every camera (pose_covariances()).
  AdjustResult Adjust(bool final, bool covariance = false);
  // Per-camera reprojection thresholds: max(outlier_threshold_px, factor * robust sigma).
  std::vector<double> OutlierThresholds() const;
  // Marks every evaluable observation inlier or outlier by the thresholds; returns how
  // many changed status.
  int FilterOutliers();
  int FilterOutliers(const std::vector<double>& thresholds);
  // COPLANAR: planes among the points off the main plane (see Options); returns how
  // many were found. Refine() calls it first.
  int FindPlanes();
  // Bundle adjustment and outlier filtering rounds, then the poses' covariance.
  RefineResult Refine();
  void FailUnregistered();

  // The projector pixel of every point (NaN: not known) and the projector's image size;
  // optionally per point the side (projector px) of the largest marker drawn at its
  // centre (NaN: not known), which groups the projector's noise (noise_model.h).
  void SetProjector(const PixelMatrix& pixels, double width, double height,
                    const std::vector<double>& marker_side_px = {});
  // The lens camera `camera`'s observations were undistorted with and its uncertainty
  // (std::invalid_argument naming the problem: a camera out of range, a lens whose focal
  // length differs from the camera's intrinsics, a covariance that is not symmetric
  // positive semi-definite).
  void SetLensUncertainty(int camera, const LensUncertainty& lens);
  // How the lenses of `cameras` (each set by SetLensUncertainty first) err together:
  // their joint covariance (8n x 8n, the k-th camera in rows and columns 8k to 8k + 7),
  // whose diagonal blocks are the lenses' own covariances (std::invalid_argument naming
  // the problem otherwise, or when it is not symmetric positive semi-definite).
  void SetLensCrossCovariances(const std::vector<int>& cameras, const Eigen::MatrixXd& joint);
  // Where the projector draws point `point`: on the surface ProjectedPlane names (false
  // without a map).
  bool ProjectorPrediction(int point, Eigen::Vector3d* X) const;
  // The plane the projector draws point `point` on: a raised surface (a table top) whose
  // reconstructed points' projector pixels surround the point's, else the main plane (0);
  // -1 without a projector pixel.
  int ProjectedPlane(int point) const;

  // State.
  int num_cameras() const { return static_cast<int>(cameras_.size()); }
  int num_points() const { return num_points_; }
  const Options& options() const { return options_; }
  bool registered(int camera) const { return registered_[camera]; }
  const std::vector<std::string>& failure_reasons() const { return failure_; }
  const ba::PoseMatrix& poses() const { return poses_; }
  const ba::PointMatrix& points() const { return points_; }
  const std::vector<bool>& reconstructed() const { return reconstructed_; }
  const std::vector<bool>& active() const { return active_; }
  const Eigen::Vector4d& plane() const { return plane_; }
  // COPLANAR: the other planes found, and per point its plane (0 the main one, k >= 1
  // more_planes()[k - 1], -1 off every plane).
  const std::vector<Eigen::Vector4d>& more_planes() const { return more_planes_; }
  const std::vector<int>& point_plane() const { return point_plane_; }
  int gauge_camera() const { return gauge_camera_; }
  const Eigen::VectorXi& camera_index() const { return camera_index_; }
  const Eigen::VectorXi& point_index() const { return point_index_; }
  std::vector<int> registration_order() const { return order_; }
  // Per camera after Refine(): covariance of [dtheta, dt] (cam_from_world, R = Exp(dtheta)
  // R_hat) relative to the gauge camera, scaled by the residuals' variance; empty when
  // not computed or not determined.
  const std::vector<ba::Matrix6d>& pose_covariances() const { return pose_covariances_; }
  // The same jointly (6 x 6 blocks per camera pair, NaN for cameras out of the solve), and
  // per camera the noise (px, 1 sigma per coordinate) this covariance stands for: its
  // weight's share of the residuals' variance. Empty when not computed.
  const Eigen::MatrixXd& pose_covariance() const { return pose_covariance_; }
  // With lenses (SetLensUncertainty): pose_covariance() includes their share (the
  // per-camera pose_covariances() do not: they tell how well the centres fix each pose
  // given the lenses, which the sigmas and the weak flag report), and these
  // give the poses' covariance with the lenses (6C x 8C, camera c's lens in columns 8c
  // to 8c + 7) and the lenses' own (8C x 8C; zero for a camera without one). Empty
  // when not computed or without lenses.
  const Eigen::MatrixXd& pose_lens_covariance() const { return pose_lens_covariance_; }
  const Eigen::MatrixXd& lens_covariance() const { return lens_covariance_; }
  bool has_lens(int camera) const { return lenses_[camera].has_value(); }
  const std::vector<double>& covariance_noise_px() const { return covariance_noise_px_; }
  // Projector after an adjustment: per plane its map, the lens; per group of points
  // (projector_group_sides_px: the largest marker's side, NaN for the points whose side
  // is not known) the maps' noise (projector px; NaN until estimated); per camera its
  // centres' noise (px, NaN until estimated).
  const std::vector<ba::ProjectorSurface>& projector_surfaces() const { return projector_surfaces_; }
  const Eigen::Vector2d& projector_lens() const { return projector_lens_; }
  // The projector's optical centre where the floor's relief places it (NaN without one).
  const Eigen::Vector3d& projector_centre() const { return projector_centre_; }
  std::vector<double> projector_sigma_px() const;
  const std::vector<double>& projector_group_sides_px() const { return projector_group_side_px_; }
  const std::vector<double>& camera_sigma_px() const { return camera_sigma_px_; }
  // Per camera after Refine(): the angle (deg) to the mirror pose its view of the floor
  // does not rule out (0 when it does); its rotation is known no better.
  const std::vector<double>& ambiguity_deg() const { return ambiguity_deg_; }
  // Residuals of the active observations of registered cameras and reconstructed
  // points; NaN elsewhere.
  PixelMatrix Residuals() const;
  // Residuals of every observation of a registered camera and a reconstructed point.
  PixelMatrix AllResiduals() const;
  // View score of a camera over all its observations.
  int ViewScore(int camera) const;

 private:
  Eigen::Vector2d Ray(int observation) const;
  // COPLANAR: the plane point of the views that agree (see the definition); false when
  // none do.
  bool PlanePointByConsensus(const std::vector<geometry::View>& views, const std::vector<double>& focal,
                             const Eigen::Vector4d& plane, Eigen::Vector3d* X) const;
  bool TriangulatePoint(const std::vector<geometry::View>& views, Eigen::Vector3d* X) const;
  double Focal(int camera) const;
  std::vector<int> ComponentSizes() const;
  std::vector<int> CommonObservations(int camera1, int camera2, std::vector<int>* second) const;
  void SetInitialStructure(int camera1, int camera2, const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                           const Eigen::Vector3d& n);
  void ResetStructure();
  // Places `point` from its registered views (coplanar: on a plane when they agree; seen
  // once, on plane `alone_on`, the main plane when -1).
  bool ReconstructPoint(int point, int alone_on = -1);
  std::vector<Eigen::Matrix3d> Rotations() const;  // per camera, from the poses
  bool InFront(int observation, const std::vector<Eigen::Matrix3d>& rotations) const;
  int ThirdCamera(int camera1, int camera2) const;
  void StoreCovariances(const ba::Result& solved, const ba::Data& data, const std::vector<int>& cameras, int points);
  // The lenses' covariance and their share of the poses' (see pose_lens_covariance()).
  void StoreLensCovariances(const ba::Result& solved, const ba::Data& data, const std::vector<int>& cameras);
  // Data::lens_block and lens_jacobians of an adjustment of `cameras`.
  void AddLenses(const std::vector<int>& cameras, ba::Data* data) const;
  bool KnownPoint(int point, Eigen::Vector3d* X) const;
  // True when the points of observations[k], k in subset, all lie on one plane (placed on
  // it, or drawn on it by the projector).
  bool AllOnOnePlane(const std::vector<int>& observations, const std::vector<int>& subset) const;
  // True when observation i is its point's only active view among the registered cameras.
  bool OnlyView(int observation) const;
  // True when OnlyView(observation) and its camera's pose misses the projector's
  // prediction of the point by more than the PnP threshold (AddPoints leaves such a
  // point for the refinement's planes).
  bool ProjectorContradictsSingleView(int observation) const;
  // The projector-pixel outline of every raised surface's reconstructed points
  // (surface_outlines_), once the planes are found.
  void OutlineSurfaces();
  // Points seen by one camera placed again on the plane whose projector-to-camera
  // homography explains them, and those AddPoints left out placed on it for the first
  // time (on the main plane where no plane explains them).
  void PlaceSingleViewPointsOnTheirSurfaces();
  int MinPnpPoints() const {
    return HasProjector() && !projector_surfaces_.empty()
               ? std::min(options_.min_pnp_points, options_.min_projector_pnp_points)
               : options_.min_pnp_points;
  }
  // Per camera noise used as weights: the estimate, else the robust sigma of its residuals.
  std::vector<double> WeightingSigmas() const;
  void EstimateNoise();
  // Groups the points with a projector pixel by their marker side (SetProjector).
  void GroupProjectorPoints(const std::vector<double>& marker_side_px);
  // Decides relief_on_ (ReliefTest); the state is left at the flat solution.
  ReliefTest TestRelief();
  // One step of the noise estimate applied (with the prior towards the pooled noise;
  // pool_projector: every projector group gets the noise of all); false when no
  // camera's residuals tell the noise.
  bool UpdateNoise(const NoiseEstimate& estimate, bool pool_projector);
  void CheckPlanarAmbiguity();
  bool NoiseSettled(const std::vector<double>& before, const std::vector<double>& projector_before) const;
  // The largest range, along any axis, of the given points that lie on the main plane
  // (between their 1st and 99th percentiles).
  double MainPlaneExtent(const std::vector<int>& points) const;
  bool HasProjector() const { return options_.use_projector && projector_.rows() == num_points_ && options_.model == ba::Model::kCoplanar; }

  std::vector<Camera> cameras_;
  int num_points_;
  Eigen::VectorXi camera_index_, point_index_;
  PixelMatrix observed_;
  Options options_;
  std::vector<std::vector<int>> camera_observations_, point_observations_;

  std::vector<bool> registered_;
  std::vector<std::string> failure_;
  ba::PoseMatrix poses_;
  ba::PointMatrix points_;
  std::vector<bool> reconstructed_;
  std::vector<bool> active_;
  Eigen::Vector4d plane_ = Eigen::Vector4d(0, 0, 1, 1);
  std::vector<Eigen::Vector4d> more_planes_;
  std::vector<int> point_plane_;
  std::vector<bool> single_view_;  // COPLANAR: placed on the main plane from one view
  int gauge_camera_ = -1;
  std::vector<int> order_;
  std::vector<ba::Matrix6d> pose_covariances_;
  Eigen::MatrixXd pose_covariance_;
  Eigen::MatrixXd pose_lens_covariance_, lens_covariance_;
  std::vector<std::optional<LensUncertainty>> lenses_;
  Eigen::MatrixXd lens_cross_covariance_;  // 8C x 8C, off-diagonal blocks only; empty: none given
  std::vector<double> covariance_noise_px_;
  ba::PixelMatrix projector_;  // normalised pixels (ba/projector_cost.h), per point
  double projector_width_ = 1.0;
  Eigen::Vector2d projector_lens_ = Eigen::Vector2d::Zero();
  Eigen::Vector3d projector_centre_ = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  std::vector<ba::ProjectorSurface> projector_surfaces_;
  // Per plane, the convex hull (normalised projector pixels) of its reconstructed points;
  // empty for the main plane and for planes with too few points.
  std::vector<std::vector<cv::Point2f>> surface_outlines_;
  std::vector<int> projector_group_;           // per point, -1: no projector pixel
  std::vector<double> projector_group_side_px_;  // per group
  std::vector<double> projector_sigma_px_;       // per group
  bool projector_sigma_estimated_ = false;
  std::vector<double> camera_sigma_px_;  // NaN until estimated
  std::vector<double> ambiguity_deg_;
  bool relief_on_ = true;  // until TestRelief finds the floor flat
  bool apex_on_ = false;   // TestRelief's relief is well above the noise (kApexGainFactor)
  bool testing_relief_ = false;  // TestRelief's uneven solve: the coarser test grid
};

}  // namespace calibproj::registration
