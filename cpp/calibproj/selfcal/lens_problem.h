#pragma once
// The lens refinement's problem: the arrays of selfcal::SelfCalibrate (observations,
// lenses, poses, floor points) and which lens entries move, kept consistent as
// observations are gated and cameras left out (refinement.cc drives it); and what the
// names a user gives stand for.

#include <opencv2/core.hpp>

#include <Eigen/Core>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "calibproj/detect/lens.h"
#include "calibproj/selfcal/refinement.h"
#include "calibproj/selfcal/self_calibration.h"

namespace calibproj::selfcal {

using Lens = Eigen::Matrix<double, kLensSize, 1>;

// The lens block's entries by name, in order, and the groups they belong to.
extern const char* const kLensEntries[kLensSize];
extern const char* const kFocalGroup;
extern const char* const kPrincipalPointGroup;
extern const char* const kDistortionGroup;

// A name a user gives, the lens entries it stands for and the group it belongs to.
struct Refinable {
  const char* name;
  std::vector<int> indices;
  const char* group;
};

// nullptr for a name that stands for no entry; RefinableOf throws std::invalid_argument.
const Refinable* FindRefinable(const std::string& name);
const Refinable& RefinableOf(const std::string& name);

bool Contains(const std::vector<std::string>& names, const std::string& name);
std::vector<cv::Point2d> PointsOf(const ba::PixelMatrix& xy, const std::vector<int>& rows);
std::vector<int> RowsOfCamera(const Eigen::VectorXi& camera_index, int camera);

// The smooth part of a camera's residuals: a quadratic field over the image fitted to
// them. A lens entry held at a wrong value (a principal point given tens of pixels off)
// or a lens model that does not fit the lens leaves such a pattern, which the refined
// entries and the pose cannot take up; noise does not (the chi-square it explains is
// then about the field's 12 parameters).
struct SystematicResidual {
  double field_px = 0.0;   // RMS length of the fitted field over the camera's observations
  double chi2_drop = 0.0;  // the residuals' sum of squares it explains, in units of the noise it leaves
};

// The arrays of selfcal::SelfCalibrate and which entries move.
class Problem {
 public:
  std::vector<std::string> cameras;
  Eigen::VectorXi camera_index, point_index;
  ba::PixelMatrix observed;
  LensMatrix given;  // lenses as given: where held entries stay
  LensMatrix start;  // lenses the refinement starts from
  std::vector<LensShape> shapes;
  std::vector<std::vector<int>> refine;
  ba::PoseMatrix poses;
  FloorMatrix points;
  LensMatrix lenses;  // current values
  std::vector<std::pair<double, double>> image_sizes;
  std::vector<std::vector<std::string>> requested;  // per camera, entry names asked for
  std::vector<std::pair<std::string, int>> dropped;  // camera -> its observations

  Problem(const formats::Tracks& tracks, const IntrinsicsMap& intrinsics, const formats::Calibration& calibration,
          const RefineRequest& request, const OrderedTexts& refused, const IntrinsicsMap& given_intrinsics);

  bool Solvable() const { return !cameras.empty() && points.rows() >= 2 && camera_index.size() > 0; }
  bool Empty() const {
    return camera_index.size() == 0 ||
           std::all_of(requested.begin(), requested.end(), [](const auto& names) { return names.empty(); });
  }
  bool Dropped(const std::string& name) const {
    return std::any_of(dropped.begin(), dropped.end(), [&](const auto& item) { return item.first == name; });
  }
  int CountOf(int camera) const { return static_cast<int>(RowsOfCamera(camera_index, camera).size()); }

  Result Solve(ba::Loss loss, double loss_scale, const Options& solve) {
    Options options = solve;
    options.loss = loss;
    options.loss_scale_px = loss_scale;
    Data data{camera_index, point_index, observed, lenses, shapes, refine, poses, points};
    Result solution = SelfCalibrate(data, options);
    lenses = solution.lenses;
    poses = solution.poses;
    points = solution.points;
    return solution;
  }

  // Puts every entry not refined back to its given value; true if one moved.
  bool HoldAtGiven();
  // Keeps the observations within the gate of their camera's noise, and the points still seen twice.
  void Gate(const Result& solution, const SelfCalibrationOptions& options);
  // Takes camera c out of the problem: its focal length is not determined, and with a
  // wrong one its observations would strain the others' lenses.
  void DropCamera(int c);
  // How far the camera's observations reach from the principal point towards the
  // farthest image corner (95th percentile of their radius over the corner's).
  double Coverage(int camera) const;
  // The smooth part of camera c's residuals in `solution`; nothing when it has too few
  // observations to tell a pattern from noise.
  std::optional<SystematicResidual> Systematic(int camera, const Result& solution) const;
  // Normalised coordinates (pinhole) of up to `count` of the camera's observations.
  std::vector<Eigen::Vector2d> Seen(int camera, int count) const;
  // Per camera, the entries refined with the stage's requested ones added (not for
  // cameras in `rejected`).
  std::vector<std::vector<int>> StageEntries(const std::vector<std::string>& stage,
                                             const std::vector<std::vector<int>>& before,
                                             const std::set<int>& rejected) const;
  // Why the entries just freed do not earn their place for camera c (its residuals, in
  // units of its noise, fell by less than min_chi2_drop per entry), or "". Without this
  // test an entry that only fits noise would be kept.
  std::string Insignificant(int c, const Result& before, const Result& after, int added,
                            const SelfCalibrationOptions& options) const;

 private:
  void Keep(std::vector<bool> keep);
};

}  // namespace calibproj::selfcal
