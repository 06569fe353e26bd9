#pragma once
// How noisy each camera's centres are, and how well the projector's maps hold, from
// what the bundle adjustment leaves (variance component estimation).
//
// Each group of observations (one camera's centres; the projector pixels) has its own
// variance. A group's estimate is the sum of its squared residuals over its
// redundancy: the share of its observations not spent on determining the parameters.
// Per point, an observation's share follows from the point's information matrix N (the
// weighted sum over its observations of J^T J, J the derivative of the observation by
// the point's coordinates): 2 - tr(w J N^-1 J^T) per 2D observation. A camera's own
// pose takes 6 more, the projector's maps 8 each and its lens 2. The points are
// re-placed under the sigmas given (one linear step from the adjustment's), so the
// estimate can be iterated to its fixed point between adjustments: a camera whose
// centres mostly determine their own points (a zoomed one beside far ones) has little
// redundancy, and a single step moves its sigma only a little. Iterated with the
// bundle adjustment this converges to the weights under which every group's residuals
// match their variance, so a camera whose centres are biased (a floor texture across
// its markers) gets the sigma its residuals show, and its pose covariance widens.
//
// The projector's observations fall into groups of their own: a floor texture displaces
// a marker's apparent centre on the floor, the same way for every camera, by a share of
// the marker's size. The large markers of a first sequence then miss their projector
// pixels by far more than the small ones of a densification, and one variance for both
// would give the small ones the large ones' weight. So points are grouped by the side
// of the largest marker drawn at their centre, each group with its variance; the
// redundancy the maps and lens take is shared among the groups by their own.

#include <Eigen/Core>
#include <limits>
#include <vector>

#include "calibproj/ba/bundle_adjuster.h"

namespace calibproj::registration {

struct NoiseInputs {
  const std::vector<ba::Intrinsics>* intrinsics = nullptr;  // per camera
  const ba::PoseMatrix* poses = nullptr;
  const ba::PointMatrix* points = nullptr;
  const std::vector<bool>* registered = nullptr;
  const std::vector<bool>* reconstructed = nullptr;
  const std::vector<bool>* active = nullptr;
  const Eigen::VectorXi* camera_index = nullptr;
  const Eigen::VectorXi* point_index = nullptr;
  const ba::PixelMatrix* observed = nullptr;
  const std::vector<int>* point_plane = nullptr;          // -1: a free point
  const std::vector<Eigen::Vector4d>* planes = nullptr;   // 0 the main plane, then the others
  // Projector (may be empty): per point normalised pixel, lens, maps per plane, and its
  // width in pixels (normalised units to pixels).
  const ba::PixelMatrix* projector = nullptr;
  Eigen::Vector2d lens = Eigen::Vector2d::Zero();
  const std::vector<ba::ProjectorSurface>* surfaces = nullptr;
  double projector_width = 1.0;
  // Per point its projector group (-1: none); null: every point in group 0.
  const std::vector<int>* projector_group = nullptr;
  int gauge_camera = -1;
  // Current sigmas: per camera (px) and per projector group (projector px).
  std::vector<double> camera_sigma_px;
  std::vector<double> projector_sigma_px;
};

struct NoiseEstimate {
  std::vector<double> camera_sigma_px;  // NaN where a camera has no redundancy
  std::vector<double> camera_redundancy;
  // Per projector group; NaN where a group has no redundancy.
  std::vector<double> projector_sigma_px;
  std::vector<double> projector_redundancy;
  // All groups as one: the variance the groups' residuals show together.
  double pooled_projector_sigma_px = std::numeric_limits<double>::quiet_NaN();
};

// Every point's observations linearised once, under the adjustment's poses, maps and
// points; Estimate() then re-weights them cheaply, so the estimate can be iterated.
class NoiseProblem {
 public:
  explicit NoiseProblem(const NoiseInputs& in);
  NoiseEstimate Estimate(const std::vector<double>& camera_sigma_px,
                         const std::vector<double>& projector_sigma_px) const;

 private:
  using Block = Eigen::Matrix<double, 2, Eigen::Dynamic, 0, 2, 3>;  // d(residual)/d(point's free coordinates)
  struct Observation {
    int camera;
    Block J;
    Eigen::Vector2d error;
  };
  struct Point {
    int dof;
    std::vector<Observation> observations;
    bool has_projector = false;
    int projector_group = 0;
    Block J_projector;
    Eigen::Vector2d projector_error;  // normalised projector units
  };
  std::vector<Point> points_;
  int num_cameras_ = 0;
  int gauge_camera_ = -1;
  int projector_maps_ = 0;
  int projector_groups_ = 0;
  bool has_projector_ = false;
  double projector_width_ = 1.0;
};

NoiseEstimate EstimateNoise(const NoiseInputs& in);

}  // namespace calibproj::registration
