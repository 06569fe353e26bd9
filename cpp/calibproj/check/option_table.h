#pragma once
// Every knob of the camera check, by name, with its documentation, in one table: the
// Python binding (keyword options, calibproj.check.repair.CheckOptions and its flags) and the
// standalone executable walk it. The defaults are those of check::CheckOptions.

#include "calibproj/check/camera_check.h"

namespace calibproj::check {

template <typename Options, typename Visitor>
void VisitCheckOptions(Options& o, Visitor&& visit) {
  visit("tolerance_px", o.tolerance_px,
        "a camera has changed only when the change moves a point of the working volume (over the "
        "calibrated points, from the floor to 2 m in a metric calibration) by more than this many "
        "pixels in its image");
  visit("significance_z", o.significance_z,
        "standard normal quantile of the statistical tests (3.09: 99.9 %, one false alarm in a "
        "thousand unchanged cameras)");
  visit("min_points", o.min_points,
        "observations of calibrated points a camera needs to be tested (fewer: unknown)");
  visit("outlier_px", o.outlier_px,
        "observations farther than this from the camera's best fit are left out of its test");
  visit("model_error_px", o.model_error_px,
        "what two recordings of an unchanged camera differ by beyond the detection noise of one "
        "(px, added to it in quadrature in the statistical test)");
  visit("max_iterations", o.max_iterations, "solver iterations per fit");
}

}  // namespace calibproj::check
