#pragma once
// Self-calibration as a calibration runs it (`calibproj calibrate --refine-intrinsics` and
// `calibproj-native calibrate --refine-intrinsics` alike): from the closed-form start
// (registered again when it moved a lens), rounds of lens refinement, each followed by a
// registration that takes the lenses' covariance in; then every camera whose lens the
// refinement cannot vouch for (its focal length held, or a misfit) is marked weak, so
// that a pose resting on a lens nobody checked does not steer comparisons.
//
// The registration is the caller's: the Python driver runs it step by step, the
// executable whole; both give the same calibration.

#include <functional>
#include <string>

#include "calibproj/formats/calibration.h"
#include "calibproj/formats/tracks.h"
#include "calibproj/selfcal/refinement.h"

namespace calibproj::selfcal {

// Registers `tracks` (every camera of the input: the caller leaves out those it must)
// undistorted with `intrinsics`; `lenses` says how the refined lenses err, null before
// any refinement.
using RegisterFunction = std::function<formats::Calibration(
    const formats::Tracks& tracks, const IntrinsicsMap& intrinsics, const JointLensCovariance* lenses)>;

struct RefinedCalibration {
  formats::Calibration calibration;  // registered with the refined lenses
  formats::Tracks tracks;            // the input's tracks, re-expressed with them
  IntrinsicsMap intrinsics;          // the refined lenses, every camera of the input
  SelfCalibration result;            // the last round's reports and lens covariance
  OrderedTexts weak;                 // the cameras marked weak, with the reason
};

// The rounds above, from `first` (a calibration registered from `tracks`, undistorted
// with the user's `intrinsics`, with at least one camera registered). `log` receives
// the refinement's lines per camera.
RefinedCalibration RefineWithRegistrations(const formats::Calibration& first, const formats::Tracks& tracks,
                                           const IntrinsicsMap& intrinsics, const RefineRequest& request,
                                           const SelfCalibrationOptions& options, int num_threads,
                                           const RegisterFunction& register_tracks,
                                           const std::function<void(const std::string&)>& log);

}  // namespace calibproj::selfcal
