#pragma once
// Every knob of the self-calibration, by name, with its documentation, in one table:
// the Python binding (calibproj.selfcal.lenses.SelfCalibrationOptions and the flags
// of calibproj calibrate) and the standalone executable (its calibrate flags) walk it.
// The defaults are those of selfcal::SelfCalibrationOptions.

#include "calibproj/selfcal/refinement.h"

namespace calibproj::selfcal {

template <typename Options, typename Visitor>
void VisitSelfCalibrationOptions(Options& o, Visitor&& visit) {
  visit("max_focal_sigma", o.max_focal_sigma,
        "the focal length counts as determined when its 1-sigma uncertainty is at most this share of it");
  visit("max_principal_point_sigma_px", o.max_principal_point_sigma_px,
        "the principal point counts as determined when the 1-sigma uncertainty of cx and cy is at most this many "
        "pixels (or the camera's noise, if larger)");
  visit("max_distortion_sigma_px", o.max_distortion_sigma_px,
        "the distortion counts as determined when the 1-sigma uncertainty of the displacement it causes, RMS over "
        "the points the camera saw (elsewhere in the image nothing measured it), is at most this many pixels (or "
        "distortion_sigma_noise_ratio times the camera's noise, if larger)");
  visit("distortion_sigma_noise_ratio", o.distortion_sigma_noise_ratio,
        "see max_distortion_sigma_px; the noise is the RMS of one residual coordinate");
  visit("min_chi2_drop", o.min_chi2_drop,
        "an entry is kept only if freeing it lowers its camera's sum of squared residuals by at least this many "
        "times the camera's noise variance, so that entries which only fit noise stay held (10: about the Bayesian "
        "information criterion's ln(n) for the few thousand residuals of a camera; at 25 the small tangential "
        "terms of wide lenses were left out and biased the poses)");
  visit("first_loss_scale_px", o.first_loss_scale_px,
        "Cauchy scale of the first solve, whose start may be far off (tens of pixels at the image corners)");
  visit("outlier_gate_px", o.outlier_gate_px,
        "after the first solve an observation is kept when its residual is below this many pixels or "
        "outlier_gate_sigma_factor times its camera's robust noise, whichever is larger");
  visit("outlier_gate_sigma_factor", o.outlier_gate_sigma_factor, "see outlier_gate_px");
  visit("lens_solver_iterations", o.lens_solver_iterations, "iterations of each Ceres solve");
  visit("max_sampled_points", o.max_sampled_points,
        "observations per camera where the distortion's uncertainty is sampled");
  visit("closed_form_min_change", o.closed_form_min_change,
        "a camera whose focal length is refined starts from the closed-form planar autocalibration's when the two "
        "differ by more than this share");
  visit("rounds", o.rounds,
        "self-calibrations, each followed by a registration with its intrinsics; the second starts where the first "
        "left off, from all the observations (the first registration, with the given intrinsics, may have left "
        "many out)");
  visit("min_coverage", o.min_coverage,
        "k3 and pp are freed only for a camera whose observations reach at least this share of the way from the "
        "principal point to the farthest image corner (95th percentile)");
  visit("max_systematic_px", o.max_systematic_px,
        "a camera whose residuals, after the refinement, keep a smooth pattern (a quadratic field over the image) "
        "of more than this many pixels RMS that explains at least min_systematic_chi2 is flagged weak: a lens "
        "entry held at a wrong value (a principal point given tens of pixels off) or a lens model that does not "
        "fit leaves one, and bends the focal length refined with it while its 1-sigma stays small (a floor 6 mm "
        "uneven under the demo room: patterns of 0.04-0.1 px, focal lengths 4-7 sigma off)");
  visit("min_systematic_chi2", o.min_systematic_chi2,
        "see max_systematic_px: the chi-square (in units of the camera's noise) the pattern must explain; noise "
        "alone explains about its 12 parameters, and more than 30 three times in a thousand");
}

}  // namespace calibproj::selfcal
