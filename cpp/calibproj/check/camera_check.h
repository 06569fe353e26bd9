#pragma once
// Does a stored calibration still hold for one camera? A short check projection gives
// the camera new observations of points whose 3D positions the calibration knows (the
// check sequence shows some of the calibrated arrays again, so its points keep their
// ids). Against those fixed points the camera is fitted three ways: its pose alone,
// its focal length alone (a PTZ camera re-zoomed about its principal point), and both.
// The fit of both is compared with a reference: the same fit to the camera's own
// calibration observations when they are given (the stored camera fits its points far
// better than its sigma relative to the other cameras says, and it is against those
// points that the new observations are tested), else the stored pose with its sigmas.
//
// - statistically: the change, with the covariance of both fits (or of the fit and the
//   stored sigmas), as a chi-square (Mahalanobis distance) against its quantile at
//   significance_z;
// - practically: how far the change moves the points of the working volume (given by
//   the caller) in the camera's image, against a tolerance in pixels.
//
// A camera has changed when both say so. It is `rezoomed` when the focal length alone
// explains the observations as well as the focal length and pose together (the
// likelihood ratio of the six pose parameters is not significant), and also when both
// changed (its pose is then re-fitted too); `moved` when the pose alone explains them,
// or when the focal change it adds moves no pixel by the tolerance. Points are held
// fixed: they were placed by the unchanged cameras and the projector, so re-fitting
// against them is the repair, with every other camera and the planes held.

#include <Eigen/Core>

#include <string>
#include <vector>

#include "calibproj/ba/camera.h"

namespace calibproj::check {

struct CheckOptions {
  // A change that moves no point of the working volume by more than this in the
  // camera's image is not one, however significant.
  double tolerance_px = 0.5;
  // Standard normal quantile of the statistical tests (3.09: 99.9 %, one false alarm
  // in a thousand unchanged cameras).
  double significance_z = 3.09;
  // Observations a camera needs to be tested (a pose has six parameters).
  int min_points = 6;
  // Observations farther than this from the best fit are left out (a marker decoded
  // with a wrong id, a person's shadow).
  double outlier_px = 3.0;
  // What two recordings of an unchanged camera differ by beyond the detection noise of
  // one (px per coordinate, added to it in quadrature): a pattern shown again lands on
  // other sensor rows, floor texture and light, which move its centres by a few
  // hundredths of a pixel in ways that are alike over a region of the image. Without it
  // unchanged cameras of rendered rooms scored a chi-square of 14.8 on average where
  // 7 is noise.
  double model_error_px = 0.08;
  // Ceres iterations per fit.
  int max_iterations = 50;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

enum class Status { kUnchanged, kMoved, kRezoomed, kUnknown };

const char* StatusName(Status status);

// One camera as stored and its new observations of stored points.
struct CameraCheckInput {
  ba::Intrinsics K;                    // undistorted pinhole of the stored intrinsics
  // Their distortion (OpenCV order, at most 12 coefficients; empty: none). The
  // observations are undistorted pixels of K; with a distortion the fits compare them
  // distorted again, so that a focal change moves them as the lens does.
  std::vector<double> dist;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // stored cam_from_world
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  // The stored pose's uncertainty: rotation (rad, per axis) and centre (world units).
  double rotation_sigma = 0.0;
  double centre_sigma = 0.0;
  Eigen::Matrix3Xd points;    // world positions of the observed points (stored, held)
  Eigen::Matrix2Xd observed;  // their new undistorted pixels
  // The camera's observations the calibration was made from, of held points: the
  // reference of the change (the stored sigmas are, without them).
  Eigen::Matrix3Xd reference_points;
  Eigen::Matrix2Xd reference_observed;
  Eigen::Matrix3Xd volume;    // points of the working volume (world), for the practical test
  double width = 0.0, height = 0.0;  // image size: volume points outside it are left out
};

struct CameraCheck {
  Status status = Status::kUnknown;
  std::string reason;  // one sentence: why this status, with its figures
  int points = 0;      // observations of stored points
  int inliers = 0;     // within outlier_px of the best fit
  double noise_px = 0.0;          // the noise the tests assume (from the fit's residuals)
  double rms_before_px = 0.0;     // stored camera, over the inliers
  double rms_after_px = 0.0;      // chosen fit, over the inliers
  double rotation_change_deg = 0.0;
  double rotation_sigma_deg = 0.0;   // of the change (fit and stored)
  double centre_change = 0.0;        // world units
  double centre_sigma = 0.0;
  double focal_change = 0.0;         // relative: new focal / stored - 1
  double focal_sigma = 0.0;
  std::string reference;             // what the change is measured against
  double chi2 = 0.0;                 // Mahalanobis distance of the change, squared
  double chi2_threshold = 0.0;
  double volume_shift_px = 0.0;      // largest move of a working-volume point in the image
  double volume_shift_sigma_px = 0.0;  // its uncertainty (1 sigma) from the change's covariance
  // The camera as it is now (the stored one when unchanged).
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  double focal_scale = 1.0;
  // A changed camera's: the covariance of its fit to the held points (w, centre, focal
  // scale; R = Exp(w) R_stored, zero rows for what the fit held), from the new
  // observations alone (the held points' own uncertainty is not in it).
  Eigen::Matrix<double, 7, 7> fit_covariance = Eigen::Matrix<double, 7, 7>::Zero();
};

// The uncertainty (1 sigma, px) of the largest move of a working-volume point the camera
// sees, for a change (w, centre, focal scale) with this covariance.
double VolumeShiftSigma(const CameraCheckInput& input, const Eigen::Matrix<double, 7, 7>& covariance);

// What a check could resolve: VolumeShiftSigma of the camera's pose and focal length
// fitted to input.points (their pixels from the stored camera, each coordinate with
// noise_px of noise), as an unchanged camera's test fits them. Infinite when they do
// not fix them (fewer than six points, or degenerate).
double PredictedShiftSigma(const CameraCheckInput& input, double noise_px);

// Throws std::invalid_argument for inconsistent input (sizes, non-finite values).
CameraCheck CheckCamera(const CameraCheckInput& input, const CheckOptions& options);

}  // namespace calibproj::check
