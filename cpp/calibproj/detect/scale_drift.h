#pragma once
// Centres that drift with the marker's size. A scale's centre is the intersection of
// the diagonals of its marker's four corners; on a floor that is not flat the corners
// do not lie in one plane, and the intersection is off the image of the MSM's centre by
// the floor's curvature under the marker times the square of its side, in a direction
// set by the camera's view of the projector's ray. A floor 6 mm (rms) uneven over 1.5 m
// moves the largest scales of a far camera by 0.2-0.3 px and a camera's merged centres
// by about 0.1 px (the zoomed camera's as much), which every camera sees differently:
// a bias the bundle adjustment cannot tell from the poses.
//
// Every scale of an MSM shares its centre, so the scales' disagreement measures the
// drift per squared side, s: centre(scale) = c0 + q * s with q the squared side
// (projector pixels, over the largest pattern's). s is a field that varies smoothly
// over the floor: a kernel regression over the MSMs' projector positions estimates it
// from the MSMs kept at two scales or more, with the kernel's width chosen among a few
// by leave-one-out cross-validation, no drift (a flat floor) being one of the choices.
// Each merged centre (the mean of its kept scales) is then moved by -mean(q) * s: to
// where a marker of no size would put it.

#include <opencv2/core.hpp>

#include <vector>

#include "calibproj/detect/msm_merge.h"

namespace calibproj::detect {

struct ScaleDriftOptions {
  bool enabled = true;
  // MSMs kept at two scales of different sizes that a camera needs for its drift to be
  // estimated at all. A few MSMs let noise pass for a drift: a camera that saw 8 small
  // markers at two scales (rendered demo room, 6 mm floor, the extra projection's patch)
  // had 29 % of their held-out disagreement "predicted", and its centres moved by a
  // 0.15 px gradient across the patch that turned the zoomed camera sharing it 0.17 deg;
  // a floor's real drift was measured from 800 MSMs or more in every rendered room.
  int min_msms = 32;
  // The drift is shrunk towards none as if this many MSMs (of the median squared-side
  // spread) had measured none at every place: where few MSMs measure it, a centre is
  // moved by less.
  double prior_msms = 1.0;
  // The share of the scales' disagreement (held out) a drift must explain to be used:
  // on a flat floor noise alone lets one of the widths explain a few percent.
  double min_gain = 0.05;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

struct ScaleDriftResult {
  // The kernel's width chosen (Gaussian sigma, as a share of the larger side of the
  // box around the camera's MSMs in projector pixels; infinity: one drift for the
  // whole camera), 0 when no drift predicts the scales' disagreement better than none.
  double bandwidth = 0.0;
  int msms = 0;               // MSMs kept at two scales of different sizes
  int corrected = 0;          // centres moved (every centre, once a drift is chosen)
  double rms_shift_px = 0.0;  // root mean square of their moves
  // Leave-one-out sums of squared disagreement (px^2): without a
  // drift, and with the chosen one (equal when none was chosen).
  double disagreement_none = 0.0;
  double disagreement_chosen = 0.0;
};

// `records` and `centres` as MergeScales leaves them (records sorted by array, marker
// and scale; centres by array and marker). `side` is each record's marker side
// (projector pixels), `projector` each centre's position in projector pixels. Moves
// `centres` (MergedCentre::centre, recording the move in MergedCentre::drift).
ScaleDriftResult CorrectScaleDrift(const std::vector<ScaleRecord>& records, const std::vector<double>& side,
                                   const std::vector<cv::Point2d>& projector, std::vector<MergedCentre>* centres,
                                   const ScaleDriftOptions& options);

}  // namespace calibproj::detect
