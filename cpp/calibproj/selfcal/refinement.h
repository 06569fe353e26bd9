#pragma once
// Self-calibration's policy: which lens entries of which camera the projection
// determines, refined from a calibration made with given (possibly nominal) intrinsics.
//
// The projected floor points seen by several cameras determine the cameras' intrinsics
// as well as their poses (planar self-calibration: the floor's circular points are
// shared by every camera, so each tilted view constrains its camera's focal length, and
// rows of markers that are straight on the floor constrain the distortion). One Ceres
// problem (self_calibration.h) refines the poses, the floor points and the requested
// lens entries of every registered camera from the raw (distorted) pixels.
//
// Entries are freed in stages, each kept only if the data determine it. Observability
// comes from the covariance of the solution: a requested group of entries (focal
// length, principal point, distortion) that the data do not determine, e.g. for a
// camera looking nearly straight down or zoomed onto a small patch of floor, keeps its
// given values and is reported; the others are solved again with it held.
//
// Entries a user names: focal (fx and fy together, their ratio kept), pp (cx, cy), k1,
// k2, k3, tangential (p1, p2); none. The model refined is OpenCV's 5-coefficient one; a
// camera whose given distortion has more coefficients in use is refused.

#include <Eigen/Core>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "calibproj/formats/calibration.h"
#include "calibproj/formats/intrinsics_file.h"
#include "calibproj/formats/tracks_file.h"
#include "calibproj/selfcal/lens.h"

namespace calibproj::selfcal {

using IntrinsicsMap = std::map<std::string, formats::CameraIntrinsics>;

// An insertion-ordered map of texts (what the reports and their JSON keep in order).
using OrderedTexts = std::vector<std::pair<std::string, std::string>>;

// Whether `items` holds an entry for `key`.
bool HasKey(const OrderedTexts& items, const std::string& key);

struct SelfCalibrationOptions {
  double max_focal_sigma = 0.01;
  double max_principal_point_sigma_px = 1.0;
  double max_distortion_sigma_px = 0.3;
  double distortion_sigma_noise_ratio = 2.0;
  double min_chi2_drop = 10.0;
  double first_loss_scale_px = 2.0;
  double outlier_gate_px = 3.0;
  double outlier_gate_sigma_factor = 4.0;
  int lens_solver_iterations = 200;
  int max_sampled_points = 500;
  double closed_form_min_change = 0.1;
  int rounds = 2;
  double min_coverage = 0.5;
  double max_systematic_px = 0.03;
  double min_systematic_chi2 = 30.0;

  void Check() const;  // std::invalid_argument naming the first knob that is not a positive number
};

// The help of --refine-intrinsics, the flag of both tools' calibrate and capture.
constexpr const char* kRefineIntrinsicsHelp =
    "refine these lens entries from the projection itself, starting from the intrinsics given: focal, pp, k1, k2, "
    "k3, tangential, or none; for every camera (focal,k1,k2) or one (ceiling=none); repeatable. Entries the data do "
    "not determine keep their given values and are reported (see self_calibration.json)";

// Which lens entries to refine, per camera ("*": every camera not named).
struct RefineRequest {
  static constexpr const char* kAllCameras = "*";
  std::vector<std::pair<std::string, std::vector<std::string>>> entries;

  // From "focal,k1,k2" (every camera) and/or "CAMERA=focal,k1" items; "CAMERA=none"
  // holds that camera. std::invalid_argument naming the bad item.
  static RefineRequest Parse(const std::vector<std::string>& items);
  const std::vector<std::string>& Of(const std::string& camera) const;
  std::vector<std::string> CamerasNamed() const;
  // std::invalid_argument when the request names a camera not among `names`.
  void CheckCameras(const std::vector<std::string>& names) const;
};

// The lens block [f, cx, cy, k1, k2, p1, p2, k3] of intrinsics, and intrinsics with
// `given`'s name, size, aspect and skew ratio but the lens block `lens`.
Eigen::Matrix<double, kLensSize, 1> LensBlockOf(const formats::CameraIntrinsics& intrinsics);
formats::CameraIntrinsics WithLens(const formats::CameraIntrinsics& given, const Eigen::Matrix<double, kLensSize, 1>& lens);

// What the self-calibration did to one camera.
struct LensReport {
  std::string camera;
  std::vector<std::string> requested;
  std::vector<std::string> refined;  // entries changed from the given values
  OrderedTexts held;                 // entry -> why its given value was kept
  std::optional<double> focal_sigma;  // px
  std::optional<double> principal_point_sigma_px;
  std::optional<double> distortion_sigma_px;  // worst over the image
  std::optional<double> noise_px;             // RMS of one residual coordinate
  std::optional<double> coverage;  // how far towards the image corners the observations reach (0-1)
  bool left_out = false;           // its focal length not determined, its observations left out of the solve
  // The smooth pattern its residuals keep (SystematicResidual): RMS px, and the
  // chi-square it explains; `misfit` says why that makes its lens untrustworthy.
  std::optional<double> systematic_px, systematic_chi2;
  std::optional<std::string> misfit;
  int observations = 0;
  std::optional<Eigen::Matrix<double, kLensSize, 1>> given, result;  // lens blocks

  void Hold(const std::string& entry, const std::string& why);            // sets (keeps its place)
  void HoldIfNot(const std::string& entry, const std::string& why);       // only when not held yet
  bool IsHeld(const std::string& entry) const;
  nlohmann::ordered_json ToJson() const;
};

// Why a camera's pose is weak after the self-calibration, or nothing: its focal length
// was held (the pose rests on a focal length nobody checked), or its residuals keep a
// smooth pattern its lens does not explain (LensReport::misfit).
std::optional<std::string> WeakReason(const LensReport& report);

// How the refined lenses of `cameras` err, together: their joint covariance (8n, 8n)
// over the lens block, the k-th camera in rows and columns 8k to 8k + 7, zero outside
// the refined entries, in pixels of each camera's measured noise. Lenses fitted to the
// same floor points err together: the off-diagonal blocks say how.
struct JointLensCovariance {
  std::vector<std::string> cameras;
  Eigen::MatrixXd matrix = Eigen::MatrixXd::Zero(0, 0);

  // The joint covariance (8n, 8n) of these cameras' lenses, in their order
  // (std::invalid_argument for a camera not among `cameras`).
  Eigen::MatrixXd Among(const std::vector<std::string>& names) const;
};

struct SelfCalibration {
  IntrinsicsMap intrinsics;         // every camera of the input; unchanged where nothing was refined
  std::vector<LensReport> reports;  // per camera asked for, in the order of the tracks
  // The lenses it refined: the registration takes how they err into the poses'.
  JointLensCovariance lens_covariance;

  const LensReport* ReportOf(const std::string& camera) const;
};

// Marks weak every registered camera of `calibration` that `result` gives a WeakReason
// (its pose rests on a lens nobody checked, so it must not steer comparisons); returns
// the cameras it marked, with the reason, for the caller to report.
OrderedTexts MarkUntrustedLensesWeak(const SelfCalibration& result, formats::Calibration& calibration);

// Cameras whose lens cannot be refined, with the reason (a request naming an unknown
// camera raises std::invalid_argument).
OrderedTexts RefusedCameras(const RefineRequest& request, const IntrinsicsMap& intrinsics,
                            const std::vector<std::string>& camera_names);

// Refines the requested lens entries of the registered cameras of `calibration`.
// `tracks` are undistorted with `intrinsics`, where the refinement starts; an entry held
// keeps its value in `given` (null: `intrinsics`). A later round passes the first
// round's result as `intrinsics`, the user's values as `given` and the first round's
// reports as `earlier`: the entries it chose are refined again, from the registration
// its intrinsics allowed, without choosing anew. The result's intrinsics are to be used
// with tracks converted by ConvertTracks. `log` receives a line per camera.
SelfCalibration SelfCalibrate(const formats::Tracks& tracks, const IntrinsicsMap& intrinsics,
                              const formats::Calibration& calibration, const RefineRequest& request,
                              const SelfCalibrationOptions& options, int num_threads, const IntrinsicsMap* given,
                              const std::vector<LensReport>* earlier,
                              const std::function<void(const std::string&)>& log);

// Intrinsics to start the refinement from: the given ones, but for a camera whose focal
// length is to be refined and disagrees by more than options.closed_form_min_change
// with the closed-form planar autocalibration (planar_autocalibration.h), that one.
// Cameras whose focal length is not refined count as known.
IntrinsicsMap ClosedFormStart(const formats::Tracks& tracks, const IntrinsicsMap& intrinsics,
                              const formats::Calibration& calibration, const RefineRequest& request,
                              const SelfCalibrationOptions& options, const std::function<void(const std::string&)>& log);

// Tracks undistorted with `given` re-expressed as undistorted with `refined` (a camera
// whose intrinsics are the same in both is left as it is).
formats::Tracks ConvertTracks(const formats::Tracks& tracks, const IntrinsicsMap& given, const IntrinsicsMap& refined);

constexpr const char* kSelfCalibrationFile = "self_calibration.json";

// self_calibration.json: per camera what was refined or held and why, the
// uncertainties, and the intrinsics given (tracks undistorted with them are converted
// by ConvertTracks), as DumpSchemaJson text.
std::string SelfCalibrationJson(const SelfCalibration& result, const IntrinsicsMap& given,
                                const SelfCalibrationOptions& options);

}  // namespace calibproj::selfcal
