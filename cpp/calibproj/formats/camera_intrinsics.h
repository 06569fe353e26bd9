#pragma once
// The one camera type: a camera's pinhole matrix, OpenCV distortion and image size, and
// the lens's mappings between distorted image pixels, undistorted pixels of the same K
// (what tracks hold) and normalised coordinates. Python's calibproj.formats.intrinsics.
// Intrinsics is this type, bound.

#include <Eigen/Core>

#include <array>
#include <cstddef>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace calibproj::formats {

// The lengths of distortion vectors OpenCV takes: [k1 k2 p1 p2], + k3, + k4 k5 k6
// (rational), + s1..s4 (thin prism), + tau_x tau_y (tilt).
inline constexpr std::array<std::size_t, 5> kDistortionLengths = {4, 5, 8, 12, 14};

// (N, 2) pixels or normalised coordinates, one point per row.
using Points2d = Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>;

struct CameraIntrinsics {
  std::string name;
  bool has_resolution = false;
  double width = 0.0, height = 0.0;
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  std::vector<double> dist;  // OpenCV order [k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4 tx ty]

  // The image size, or twice the principal point when the file gives none.
  double ImageWidth() const { return has_resolution ? width : 2.0 * K(0, 2) + 1.0; }
  double ImageHeight() const { return has_resolution ? height : 2.0 * K(1, 2) + 1.0; }

  bool HasDistortion() const;
  // Undistorted pixels (same K) of distorted pixels. Iterates until the result, distorted
  // again, is within 1e-9 px (OpenCV's default 5 iterations leave errors of several pixels
  // in the corners of a wide-angle image); it converges wherever the distortion is
  // one-to-one (MaxMonotonicRadius).
  Points2d UndistortPixels(const Points2d& distorted) const;
  // Distorted pixels of undistorted pixels (same K).
  Points2d DistortPixels(const Points2d& undistorted) const;
  // Pinhole normalised coordinates K^-1 [u, v, 1] of undistorted pixels.
  Points2d Normalize(const Points2d& undistorted) const;
  // Distorted pixels of normalised coordinates (X/Z, Y/Z).
  Points2d ProjectNormalized(const Points2d& normalized) const;
  // Normalised radius up to which the radial distortion is one-to-one, sampled every
  // `step`: a polynomial distortion folds back beyond some radius, so points far outside
  // the field of view can land inside the image. `limit` when it stays monotonic.
  double MaxMonotonicRadius(double limit = 4.0, double step = 1e-3) const;
  // Which pixels lie inside the image, `margin_px` away from its border;
  // std::invalid_argument when the resolution is not known.
  std::vector<bool> Contains(const Points2d& pixels, double margin_px = 0.0) const;
};

// What is wrong with these values, or "": K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]
// with positive focal lengths (OpenCV's distortion ignores a skew term), dist 4, 5, 8,
// 12 or 14 finite coefficients, the image at most limits::kMaxImageSide per side.
std::string IntrinsicsProblem(const CameraIntrinsics& intrinsics);

// OpenCV's radial, tangential and thin-prism distortion of one camera, written out with
// its coefficients read once, for code that maps points one at a time. The tilted-sensor
// model is not written out (`tilted`: use ProjectNormalized, through OpenCV).
struct DistortionModel {
  explicit DistortionModel(const CameraIntrinsics& intrinsics);

  // (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6).
  double Radial(double r2) const {
    return (1.0 + r2 * (c[0] + r2 * (c[1] + r2 * c[4]))) / (1.0 + r2 * (c[5] + r2 * (c[6] + r2 * c[7])));
  }

  // Distorted pixel (u, v) of the normalised point (x, y).
  void Project(double x, double y, double* u, double* v) const {
    const double r2 = x * x + y * y, radial = Radial(r2);
    const double xd = x * radial + 2.0 * c[2] * x * y + c[3] * (r2 + 2.0 * x * x) + r2 * (c[8] + c[9] * r2);
    const double yd = y * radial + c[2] * (r2 + 2.0 * y * y) + 2.0 * c[3] * x * y + r2 * (c[10] + c[11] * r2);
    *u = (K(0, 0) * xd + K(0, 1) * yd) + K(0, 2);
    *v = (K(1, 0) * xd + K(1, 1) * yd) + K(1, 2);
  }

  std::array<double, 12> c{};  // k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4, zero beyond dist
  bool tilted = false;
  Eigen::Matrix3d K;
};

// Checked intrinsics (an empty dist means none: five zeros); std::invalid_argument
// "intrinsics of '<name>': <problem>".
CameraIntrinsics MakeIntrinsics(const std::string& name, std::optional<std::pair<double, double>> resolution,
                                const Eigen::Matrix3d& K, std::vector<double> dist);

// A pinhole with the horizontal field of view `fov_deg`, square pixels, the principal
// point at the image centre and no distortion: where a camera without any calibration
// starts (calibrate --nominal-fov).
CameraIntrinsics NominalIntrinsics(const std::string& name, int width, int height, double fov_deg);

}  // namespace calibproj::formats
