#include "calibproj/formats/camera_intrinsics.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

#include "calibproj/common/limits.h"
#include "calibproj/formats/files.h"

namespace calibproj::formats {

namespace {

constexpr int kUndistortMaxIterations = 200;
constexpr double kUndistortEpsilonPx = 1e-9;

std::string PythonMatrix(const Eigen::Matrix3d& K) {
  std::string out = "[";
  for (int r = 0; r < 3; ++r) {
    out += r ? ", [" : "[";
    for (int c = 0; c < 3; ++c) out += (c ? ", " : "") + PythonFloat(K(r, c));
    out += "]";
  }
  return out + "]";
}

bool Tilted(const std::vector<double>& dist) {
  return dist.size() == 14 && (dist[12] != 0.0 || dist[13] != 0.0);
}

std::vector<cv::Point2d> CvPoints(const Points2d& rows) {
  std::vector<cv::Point2d> out(rows.rows());
  for (Eigen::Index i = 0; i < rows.rows(); ++i) out[i] = {rows(i, 0), rows(i, 1)};
  return out;
}

Points2d Rows(const std::vector<cv::Point2d>& points) {
  Points2d out(points.size(), 2);
  for (std::size_t i = 0; i < points.size(); ++i) out.row(i) << points[i].x, points[i].y;
  return out;
}

cv::Matx33d CvMatrix(const Eigen::Matrix3d& K) {
  cv::Matx33d out;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) out(r, c) = K(r, c);
  }
  return out;
}

}  // namespace

bool CameraIntrinsics::HasDistortion() const {
  return std::any_of(dist.begin(), dist.end(), [](double c) { return c != 0.0; });
}

Points2d CameraIntrinsics::UndistortPixels(const Points2d& distorted) const {
  if (distorted.rows() == 0 || !HasDistortion()) return distorted;
  std::vector<cv::Point2d> out;
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, kUndistortMaxIterations,
                                  kUndistortEpsilonPx);
  const cv::Matx33d camera = CvMatrix(K);
  cv::undistortPoints(CvPoints(distorted), out, camera, dist, cv::Matx33d::eye(), camera, criteria);
  return Rows(out);
}

Points2d CameraIntrinsics::DistortPixels(const Points2d& undistorted) const {
  if (undistorted.rows() == 0 || !HasDistortion()) return undistorted;
  return ProjectNormalized(Normalize(undistorted));
}

Points2d CameraIntrinsics::Normalize(const Points2d& undistorted) const {
  Points2d out(undistorted.rows(), 2);
  for (Eigen::Index i = 0; i < undistorted.rows(); ++i) {
    out(i, 0) = (undistorted(i, 0) - K(0, 2)) / K(0, 0);
    out(i, 1) = (undistorted(i, 1) - K(1, 2)) / K(1, 1);
  }
  return out;
}

Points2d CameraIntrinsics::ProjectNormalized(const Points2d& normalized) const {
  if (Tilted(dist)) {  // the tilted-sensor model, through OpenCV
    if (normalized.rows() == 0) return normalized;
    std::vector<cv::Point3d> rays(normalized.rows());
    for (Eigen::Index i = 0; i < normalized.rows(); ++i) rays[i] = {normalized(i, 0), normalized(i, 1), 1.0};
    std::vector<cv::Point2d> out;
    cv::projectPoints(rays, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), CvMatrix(K), dist, out);
    return Rows(out);
  }
  const DistortionModel model(*this);
  Points2d out(normalized.rows(), 2);
  for (Eigen::Index i = 0; i < normalized.rows(); ++i) {
    model.Project(normalized(i, 0), normalized(i, 1), &out(i, 0), &out(i, 1));
  }
  return out;
}

DistortionModel::DistortionModel(const CameraIntrinsics& intrinsics)
    : tilted(Tilted(intrinsics.dist)), K(intrinsics.K) {
  std::copy_n(intrinsics.dist.begin(), std::min(intrinsics.dist.size(), c.size()), c.begin());
}

double CameraIntrinsics::MaxMonotonicRadius(double limit, double step) const {
  if (!(step > 0.0) || !(limit >= step) || limit / step > 1e8) {
    throw std::invalid_argument("max_monotonic_radius: need 0 < step <= limit and at most 1e8 steps, got limit=" +
                                PythonFloat(limit) + ", step=" + PythonFloat(step));
  }
  // The radii step, 2 step, ... up to limit, as numpy.arange(step, limit + step, step).
  const double delta = (step + step) - step;
  const auto count = static_cast<std::size_t>(std::ceil(((limit + step) - step) / step));
  const DistortionModel model(*this);
  bool finite = true;
  double previous = 0.0;
  for (std::size_t i = 0; i < count; ++i) {
    const double radius = step + static_cast<double>(i) * delta;
    const double distorted = radius * model.Radial(radius * radius);
    finite = finite && std::isfinite(distorted);
    if (i > 0 && !(distorted > previous)) return step + static_cast<double>(i - 1) * delta;
    previous = distorted;
  }
  return finite ? limit : step;
}

std::vector<bool> CameraIntrinsics::Contains(const Points2d& pixels, double margin_px) const {
  if (!has_resolution) throw std::invalid_argument("intrinsics of " + PythonRepr(name) + ": resolution unknown");
  std::vector<bool> inside(pixels.rows());
  for (Eigen::Index i = 0; i < pixels.rows(); ++i) {
    const double u = pixels(i, 0), v = pixels(i, 1);
    inside[i] = u >= margin_px && u <= width - 1 - margin_px && v >= margin_px && v <= height - 1 - margin_px;
  }
  return inside;
}

std::string IntrinsicsProblem(const CameraIntrinsics& in) {
  const Eigen::Matrix3d& K = in.K;
  bool finite = K.allFinite();
  for (double d : in.dist) finite = finite && std::isfinite(d);
  if (!finite) return "K and dist must be finite numbers";
  if (K(0, 0) <= 0 || K(1, 1) <= 0) {
    return "focal lengths must be positive, got fx=" + PythonFloat(K(0, 0)) + ", fy=" + PythonFloat(K(1, 1));
  }
  if (K(0, 1) != 0 || K(1, 0) != 0 || K(2, 0) != 0 || K(2, 1) != 0 || K(2, 2) != 1) {
    // OpenCV's distortion functions ignore a skew term, so none is accepted.
    return "K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got " + PythonMatrix(K);
  }
  if (std::find(kDistortionLengths.begin(), kDistortionLengths.end(), in.dist.size()) == kDistortionLengths.end()) {
    return "dist must have 4, 5, 8, 12, 14 coefficients, got " + std::to_string(in.dist.size());
  }
  if (in.has_resolution && !(in.width > 0 && in.width == std::floor(in.width) && in.height > 0 &&
                             in.height == std::floor(in.height))) {
    return "resolution must be two positive integers [width, height], got [" + PythonFloat(in.width) + ", " +
           PythonFloat(in.height) + "]";
  }
  // Without a resolution the principal point gives the image size.
  const double width = in.ImageWidth(), height = in.ImageHeight();
  if (!(width > 0 && width <= limits::kMaxImageSide && height > 0 && height <= limits::kMaxImageSide)) {
    return "image size must be at most " + std::to_string(limits::kMaxImageSide) + " pixels per side, got " +
           FormatNumber("%g", width) + "x" + FormatNumber("%g", height);
  }
  return "";
}

CameraIntrinsics MakeIntrinsics(const std::string& name, std::optional<std::pair<double, double>> resolution,
                                const Eigen::Matrix3d& K, std::vector<double> dist) {
  CameraIntrinsics in;
  in.name = name;
  in.has_resolution = resolution.has_value();
  if (resolution) std::tie(in.width, in.height) = *resolution;
  in.K = K;
  in.dist = dist.empty() ? std::vector<double>(5, 0.0) : std::move(dist);
  if (const std::string problem = IntrinsicsProblem(in); !problem.empty()) {
    throw std::invalid_argument("intrinsics of " + PythonRepr(name) + ": " + problem);
  }
  return in;
}

CameraIntrinsics NominalIntrinsics(const std::string& name, int width, int height, double fov_deg) {
  const double focal = 0.5 * width / std::tan(fov_deg * M_PI / 180.0 / 2.0);
  Eigen::Matrix3d K;
  K << focal, 0.0, (width - 1) / 2.0, 0.0, focal, (height - 1) / 2.0, 0.0, 0.0, 1.0;
  return MakeIntrinsics(name, std::make_pair(double(width), double(height)), K, {});
}

}  // namespace calibproj::formats
