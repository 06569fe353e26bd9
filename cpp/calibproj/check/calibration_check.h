#pragma once
// Every camera of a stored calibration checked against a check projection's tracks, the
// verdict on whether the stored calibration can be trusted, and the repair: the one
// implementation behind `calibproj check` and `calibproj-native check`.
//
// The stored points stand for the floor and the cameras that placed them. If the
// cameras that agree with them are not a clear majority of those tested, the floor, the
// projector or most cameras changed: the check says so and nothing is repaired, since
// it cannot tell which side moved.

#include <Eigen/Core>

#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "calibproj/check/camera_check.h"
#include "calibproj/formats/calibration.h"
#include "calibproj/formats/intrinsics_file.h"
#include "calibproj/formats/tracks_file.h"

namespace calibproj::check {

// One camera's verdict: unchanged, moved, rezoomed, "not seen" (no observation of a
// calibrated point: it keeps its stored pose) or unknown (not testable, said why).
struct CameraVerdict {
  std::string status;
  std::string reason;
  int points = 0;
  int inliers = 0;
  // The test's figures (CameraCheck), for the cameras tested.
  std::optional<CameraCheck> figures;

  bool Tested() const;   // unchanged, moved or rezoomed
  bool Changed() const;  // moved or rezoomed
};

struct CalibrationCheck {
  std::vector<std::pair<std::string, CameraVerdict>> cameras;  // registered, then failed ones
  bool trusted = false;  // the unchanged cameras are a clear majority of those tested
  std::string message;
  std::string unit = "arbitrary";

  std::vector<std::string> Tested() const;
  std::vector<std::string> Changed() const;
  const CameraVerdict* Find(const std::string& name) const;
};

// The working volume of the practical test: a 9 x 9 grid over the floor under the
// calibrated points at 5 heights, from the floor up to 2 m (in a calibration without a
// metric unit, to 0.7 of the highest camera's height).
Eigen::Matrix3Xd WorkingVolume(const formats::Calibration& calibration);

struct CheckInputs {
  const formats::Calibration* calibration = nullptr;
  const std::map<std::string, formats::CameraIntrinsics>* intrinsics = nullptr;
  std::map<std::string, std::string> unusable;  // camera -> why it has no intrinsics
  const formats::Tracks* tracks = nullptr;         // the check projection's observations
  const formats::Tracks* stored_tracks = nullptr;  // the calibration's own (optional)
  // Why a camera gave no observation (its ingest's failure): the reason of its "not seen".
  std::map<std::string, std::string> not_seen;
};

// std::invalid_argument when the calibration has no camera or point to check against,
// or the tracks show none of its points.
CalibrationCheck CheckCalibration(const CheckInputs& inputs, const CheckOptions& options);

// The calibration as the cameras are now: the changed cameras' poses, focal lengths,
// metrics and observations (the check's) replace the stored ones.
struct Repair {
  formats::Calibration calibration;
  std::map<std::string, formats::CameraIntrinsics> intrinsics;
  formats::Tracks tracks;
};

// std::invalid_argument with the check's message when it is not trusted.
Repair Repaired(const CheckInputs& inputs, const CalibrationCheck& check, double weak_rotation_sigma_deg);

// check.json (calibproj.check/1).
std::string CheckJson(const CalibrationCheck& check);

// One line per camera under a header: status, change with its sigma, shift of the
// working volume, residuals before and after (what both commands print).
std::string CheckTable(const CalibrationCheck& check);

// The exit status of both commands (README, "Exit status"): 0 every camera confirmed or
// repaired; 3 not confirmed (a camera not seen or unknown, a change not repaired, fewer
// than two cameras tested); 4 the stored calibration cannot be trusted.
constexpr int kExitNotConfirmed = 3;
constexpr int kExitUntrusted = 4;
int CheckExitStatus(const CalibrationCheck& check, bool repaired);

}  // namespace calibproj::check
