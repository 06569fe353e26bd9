#pragma once
// Every knob of the registration, by name, with its documentation, in one table: the
// Python binding (keyword options, and calibproj.registration.driver.RegistrationOptions with
// its command-line flags, generated from it) and the standalone executable (its
// calibrate flags) all walk it, so none can miss or redefine a knob. The defaults are
// those of registration::Options.
//
// visit(name, field, help) is called once per knob; `name` is snake_case (flags use
// dashes). The enumerated knobs (ba::Model, ba::Loss) take the names of Choices<>.

#include <string>
#include <utility>
#include <vector>

#include "calibproj/registration/reconstruction.h"

namespace calibproj::registration {

// The values of an enumerated knob, by name, in the order they are documented.
template <typename Enum>
struct Choices;

template <>
struct Choices<ba::Model> {
  static const std::vector<std::pair<std::string, ba::Model>>& All() {
    static const std::vector<std::pair<std::string, ba::Model>> all = {{"coplanar", ba::Model::kCoplanar},
                                                                       {"free", ba::Model::kFree}};
    return all;
  }
};

template <>
struct Choices<ba::Loss> {
  static const std::vector<std::pair<std::string, ba::Loss>>& All() {
    static const std::vector<std::pair<std::string, ba::Loss>> all = {
        {"none", ba::Loss::kNone}, {"huber", ba::Loss::kHuber}, {"cauchy", ba::Loss::kCauchy}};
    return all;
  }
};

template <typename Enum>
std::string ChoiceName(Enum value) {
  for (const auto& [name, choice] : Choices<Enum>::All()) {
    if (choice == value) return name;
  }
  return "?";
}

// False for a name that is none of the choices.
template <typename Enum>
bool ChoiceFromName(const std::string& name, Enum* value) {
  for (const auto& [choice_name, choice] : Choices<Enum>::All()) {
    if (choice_name == name) {
      *value = choice;
      return true;
    }
  }
  return false;
}

// "a, b, c": the names of an enumerated knob's choices.
template <typename Enum>
std::string ChoiceList() {
  std::string names;
  for (const auto& [name, unused] : Choices<Enum>::All()) names += (names.empty() ? "" : ", ") + name;
  return names;
}

template <typename OptionsT, typename Visitor>
void VisitRegistrationOptions(OptionsT& o, Visitor&& visit) {
  visit("model", o.model,
        "coplanar (points on one refined plane, as in the paper's results) or free (3D "
        "points).");
  visit("homography_threshold_px", o.homography_threshold_px,
        "RANSAC threshold of the initial pair's homography, in each camera's own pixels (3 px in "
        "the paper).");
  visit("pnp_threshold_px", o.pnp_threshold_px,
        "RANSAC threshold of PnP for each new camera, in its pixels.");
  visit("ransac_max_iterations", o.ransac_max_iterations,
        "upper bound of RANSAC iterations.");
  visit("ransac_confidence", o.ransac_confidence,
        "RANSAC stops once a better model is this unlikely.");
  visit("seed", o.seed,
        "RANSAC random seed (results are reproducible for a given seed).");
  visit("min_pair_points", o.min_pair_points,
        "common points needed for the initial pair and the third camera.");
  visit("min_pnp_points", o.min_pnp_points,
        "correspondences needed to register a camera.");
  visit("min_triangulation_angle_deg", o.min_triangulation_angle_deg,
        "FREE model: parallax needed to triangulate a point.");
  visit("min_pair_parallax_deg", o.min_pair_parallax_deg,
        "median parallax the initial pair's points need (two cameras at nearly the same place "
        "determine neither the plane nor the points).");
  visit("outlier_threshold_px", o.outlier_threshold_px,
        "smallest reprojection error at which an observation is removed (1 px in the paper).");
  visit("outlier_sigma_factor", o.outlier_sigma_factor,
        "the threshold is max(outlier_threshold_px, factor * sigma) with sigma a robust estimate "
        "of each camera's noise; 0 keeps the fixed threshold.");
  visit("max_refine_rounds", o.max_refine_rounds,
        "bundle adjustment and outlier removal rounds at the end.");
  visit("view_score_levels", o.view_score_levels,
        "levels of the visibility pyramid of the view score.");
  visit("loss", o.loss,
        "robust loss of the bundle adjustment (none, huber, cauchy).");
  visit("loss_scale_px", o.loss_scale_px,
        "scale of the robust loss in pixels.");
  visit("num_threads", o.num_threads,
        "threads of the bundle adjustment.");
  visit("intermediate_ba_iterations", o.intermediate_ba_iterations,
        "iterations of the bundle adjustment after each camera.");
  visit("final_ba_iterations", o.final_ba_iterations,
        "iterations of the final bundle adjustments.");
  visit("weak_rotation_sigma_deg", o.weak_rotation_sigma_deg,
        "a camera whose rotation is known worse than this (1 sigma along the worst axis, from the "
        "final bundle adjustment's covariance) is reported as weak: few points, a small or near- "
        "affine view.");
  visit("max_planes", o.max_planes,
        "coplanar model: points off the floor (a table, a cart left in the projection) are "
        "triangulated, and up to this many more planes are found among them (RANSAC) and refined "
        "with the rest (0: none).");
  visit("min_plane_points", o.min_plane_points,
        "points a plane needs to be found.");
  visit("plane_distance", o.plane_distance,
        "a point belongs to a plane within this distance, in units of the first camera's height "
        "above the floor.");
  visit("use_projector", o.use_projector,
        "coplanar model with the sequence known: tie every centre's floor (or table) position to "
        "its projector pixel through each surface's projector map (a homography and the projector "
        "lens's radial distortion, refined with the rest), so that centres one camera alone sees "
        "count too, and a camera can be registered on centres no other camera placed.");
  visit("min_projector_pnp_points", o.min_projector_pnp_points,
        "centres a camera needs to be registered once the projector places them.");
  visit("estimate_noise", o.estimate_noise,
        "weight each camera by the noise its own centres show and the projector by its maps' "
        "(variance components), and scale the pose covariance with them; off: one noise for every "
        "camera.");
  visit("projector_sigma_px", o.projector_sigma_px,
        "the projector maps' noise (projector pixels) until it is estimated, or for good with "
        "estimate_noise off.");
  visit("error_correlation", o.error_correlation,
        "the correlation of the projector's errors (and of one camera's centre errors with "
        "shared_error_shift 0): a share of each error that its centres have in common (the lens "
        "model, blur, a floor's texture) is not averaged away by their number, so the pose "
        "covariance counts N centres as N / (1 + (N - 1) * error_correlation) independent ones. The "
        "poses do not depend on it.");
  visit("shared_error_shift", o.shared_error_shift,
        "each camera's shared errors as a shift that all its centres take (a bias of its detections, "
        "its principal point, a timing offset), of this many times its noise along each image axis, "
        "propagated into the covariance: a camera's shift moves its own pose and what it places, not "
        "the local shape of the patch it measures for a zoomed camera. error_correlation then "
        "discounts the projector's residuals and the refined lenses' covariance only. 0: every "
        "camera discounted by error_correlation instead. The poses do not depend on it.");
  visit("shared_error_field", o.shared_error_field,
        "each camera's shared errors also as a smooth field over its image: independent shifts at the "
        "nodes of a 3 x 3 grid over its observations, bilinear between them, of this many times its "
        "noise, propagated into the covariance as the shift is. A far camera's errors that vary across "
        "its view tilt an uneven floor's relief under a zoomed camera's patch, which a uniform shift "
        "does not: on the rendered rooms with a floor 6 mm uneven the default leaves the zoomed camera "
        "1.3-2.6 sigma off, where 0 (off) left it 2.2-5.2. The poses do not depend on it.");
  visit("floor_relief", o.floor_relief,
        "coplanar: the expected root mean square height of the floor's unevenness, as a share of "
        "the extent of the centres on it (0.001: 3 mm over a 3 m projection). The floor's centres "
        "may leave its plane by a smooth relief with that prior, which cameras seeing them from "
        "several directions measure; a camera zoomed onto a patch of floor is then not handed the "
        "patch's slope as its own tilt. 0: an exactly flat floor.");
  visit("relief_cells", o.relief_cells,
        "coplanar, with a relief: the relief grid's cells across the larger extent of the floor's "
        "centres; a floor that rises and falls over shorter distances than a cell needs more. A "
        "zoomed camera sees its patch's slope as its own tilt: on the rendered 9-camera room (a "
        "floor 3 mm uneven, bilinear relief), 24 cells leave it 0.018-0.047 deg off where 12 left "
        "0.031-0.082 deg (3 seeds). Whether the floor is uneven at all is tested on a grid half "
        "as fine.");
  visit("relief_cubic", o.relief_cubic,
        "coplanar, with a relief: its height between the grid's nodes is a cubic B-spline, whose "
        "slope and curvature run on across the cells' edges; off: bilinear between the cells' "
        "corners, whose kinks a camera zoomed onto the floor sees at about a pixel per millimetre. "
        "Off by default: the refinement takes 2.5-4x as long with it, for a zoomed camera 0-25 % "
        "nearer the truth on the rendered rooms measured.");
}

}  // namespace calibproj::registration
