#include "calibproj/selfcal/lens_problem.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>

#include "calibproj/formats/files.h"

namespace calibproj::selfcal {

using formats::FormatNumber;

const char* const kLensEntries[kLensSize] = {"focal", "cx", "cy", "k1", "k2", "p1", "p2", "k3"};
const char* const kFocalGroup = "focal";
const char* const kPrincipalPointGroup = "principal point";
const char* const kDistortionGroup = "distortion";

namespace {

const std::vector<Refinable>& RefinableEntries() {
  static const std::vector<Refinable> all = {{"focal", {kFocal}, kFocalGroup},
                                             {"pp", {kCx, kCy}, kPrincipalPointGroup},
                                             {"k1", {kK1}, kDistortionGroup},
                                             {"k2", {kK2}, kDistortionGroup},
                                             {"k3", {kK3}, kDistortionGroup},
                                             {"tangential", {kP1, kP2}, kDistortionGroup}};
  return all;
}

}  // namespace

const Refinable* FindRefinable(const std::string& name) {
  for (const Refinable& entry : RefinableEntries()) {
    if (name == entry.name) return &entry;
  }
  return nullptr;
}

const Refinable& RefinableOf(const std::string& name) {
  const Refinable* entry = FindRefinable(name);
  if (entry == nullptr) throw std::invalid_argument("unknown lens entry '" + name + "'");
  return *entry;
}

bool Contains(const std::vector<std::string>& names, const std::string& name) {
  return std::find(names.begin(), names.end(), name) != names.end();
}

std::vector<cv::Point2d> PointsOf(const ba::PixelMatrix& xy, const std::vector<int>& rows) {
  std::vector<cv::Point2d> out;
  out.reserve(rows.size());
  for (const int i : rows) out.emplace_back(xy(i, 0), xy(i, 1));
  return out;
}

std::vector<int> RowsOfCamera(const Eigen::VectorXi& camera_index, int camera) {
  std::vector<int> rows;
  for (int i = 0; i < camera_index.size(); ++i) {
    if (camera_index(i) == camera) rows.push_back(i);
  }
  return rows;
}

namespace {

// numpy's percentile (linear interpolation between the closest ranks); NaN when empty.
double Percentile(std::vector<double> values, double q) {
  if (values.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(values.begin(), values.end());
  const double rank = q / 100.0 * static_cast<double>(values.size() - 1);
  const size_t below = static_cast<size_t>(std::floor(rank));
  const size_t above = std::min(below + 1, values.size() - 1);
  return values[below] + (rank - static_cast<double>(below)) * (values[above] - values[below]);
}

Eigen::Matrix3d Rotation(const Eigen::Vector3d& angle_axis) {
  cv::Mat R;
  cv::Rodrigues(cv::Vec3d(angle_axis(0), angle_axis(1), angle_axis(2)), R);
  Eigen::Matrix3d out;
  cv::cv2eigen(R, out);
  return out;
}

Eigen::Vector3d AngleAxis(const Eigen::Matrix3d& R) {
  cv::Mat matrix;
  cv::eigen2cv(R, matrix);
  cv::Vec3d w;
  cv::Rodrigues(matrix, w);
  return {w[0], w[1], w[2]};
}

// Floor coordinates of each point of the kept observations: the calibration's where it
// has the point, else the median of its rays' intersections with the floor z = 0.
FloorMatrix FloorPoints(const std::vector<std::string>& cameras, const Eigen::VectorXi& camera_index,
                        const Eigen::VectorXi& point_index, const ba::PixelMatrix& xy,
                        const std::vector<std::int64_t>& point_ids, const IntrinsicsMap& intrinsics,
                        const formats::Calibration& calibration) {
  std::map<std::int64_t, int> known;
  for (size_t row = 0; row < calibration.point_ids.size(); ++row) known.emplace(calibration.point_ids[row], row);
  std::vector<std::vector<Eigen::Vector2d>> hits(point_ids.size());
  for (int i = 0; i < camera_index.size(); ++i) {
    const std::string& name = cameras[camera_index(i)];
    const formats::CameraPose& pose = *calibration.PoseOf(name);
    const Eigen::Matrix3d& K = intrinsics.at(name).K;
    const Eigen::Vector3d ray = pose.R.transpose() * Eigen::Vector3d((xy(i, 0) - K(0, 2)) / K(0, 0),
                                                                     (xy(i, 1) - K(1, 2)) / K(1, 1), 1.0);
    const Eigen::Vector3d centre = pose.Centre();
    const double scale = -centre(2) / ray(2);
    if (scale > 0.0) hits[point_index(i)].push_back(centre.head<2>() + scale * ray.head<2>());
  }
  FloorMatrix points(point_ids.size(), 2);
  for (size_t p = 0; p < point_ids.size(); ++p) {
    const auto found = known.find(point_ids[p]);
    if (found != known.end()) {
      points.row(p) = calibration.points.row(found->second).head<2>();
      continue;
    }
    for (int axis = 0; axis < 2; ++axis) {
      std::vector<double> values;
      for (const auto& hit : hits[p]) values.push_back(hit(axis));
      points(p, axis) = Percentile(values, 50.0);
    }
  }
  return points;
}

}  // namespace

Problem::Problem(const formats::Tracks& tracks, const IntrinsicsMap& intrinsics,
                 const formats::Calibration& calibration, const RefineRequest& request, const OrderedTexts& refused,
                 const IntrinsicsMap& given_intrinsics) {
  std::vector<int> remap(tracks.cameras.size(), -1);
  for (size_t c = 0; c < tracks.cameras.size(); ++c) {
    const std::string& name = tracks.cameras[c];
    if (calibration.PoseOf(name) != nullptr && intrinsics.count(name)) {
      remap[c] = static_cast<int>(cameras.size());
      cameras.push_back(name);
    }
  }
  // The kept cameras' observations of points that two of them see (tracks hold one
  // observation per camera and point).
  std::vector<int> seen_by(tracks.point_ids.size(), 0);
  for (int i = 0; i < tracks.camera_index.size(); ++i) {
    if (remap[tracks.camera_index(i)] >= 0) ++seen_by[tracks.point_index(i)];
  }
  std::vector<int> point_remap(tracks.point_ids.size(), -1);
  std::vector<std::int64_t> point_ids;
  for (size_t p = 0; p < seen_by.size(); ++p) {
    if (seen_by[p] >= 2) {
      point_remap[p] = static_cast<int>(point_ids.size());
      point_ids.push_back(tracks.point_ids[p]);
    }
  }
  std::vector<int> rows;
  for (int i = 0; i < tracks.camera_index.size(); ++i) {
    if (remap[tracks.camera_index(i)] >= 0 && point_remap[tracks.point_index(i)] >= 0) rows.push_back(i);
  }
  const int n = static_cast<int>(rows.size()), num_cameras = static_cast<int>(cameras.size());
  camera_index.resize(n);
  point_index.resize(n);
  ba::PixelMatrix xy(n, 2);
  for (int k = 0; k < n; ++k) {
    camera_index(k) = remap[tracks.camera_index(rows[k])];
    point_index(k) = point_remap[tracks.point_index(rows[k])];
    xy.row(k) = tracks.xy.row(rows[k]);
  }
  observed = xy;
  for (int c = 0; c < num_cameras; ++c) {
    const std::vector<int> mine = RowsOfCamera(camera_index, c);
    const auto distorted = detect::DistortPixels(intrinsics.at(cameras[c]), PointsOf(xy, mine));
    for (size_t k = 0; k < mine.size(); ++k) observed.row(mine[k]) << distorted[k].x, distorted[k].y;
  }
  poses.resize(num_cameras, 6);
  given.resize(num_cameras, kLensSize);
  start.resize(num_cameras, kLensSize);
  for (int c = 0; c < num_cameras; ++c) {
    const std::string& name = cameras[c];
    const formats::CameraPose& pose = *calibration.PoseOf(name);
    poses.row(c) << AngleAxis(pose.R).transpose(), pose.t.transpose();
    const formats::CameraIntrinsics& in = intrinsics.at(name);
    start.row(c) = LensBlockOf(in).transpose();
    given.row(c) = LensBlockOf(given_intrinsics.at(name)).transpose();
    shapes.push_back({in.K(1, 1) / in.K(0, 0), in.K(0, 1) / in.K(0, 0)});
    image_sizes.emplace_back(in.ImageWidth(), in.ImageHeight());
    requested.push_back(HasKey(refused, name) ? std::vector<std::string>{} : request.Of(name));
  }
  points = FloorPoints(cameras, camera_index, point_index, xy, point_ids, intrinsics, calibration);
  refine.assign(num_cameras, {});
  lenses = start;
}

bool Problem::HoldAtGiven() {
  bool moved = false;
  for (int c = 0; c < static_cast<int>(cameras.size()); ++c) {
    for (int k = 0; k < kLensSize; ++k) {
      const bool refined = std::find(refine[c].begin(), refine[c].end(), k) != refine[c].end();
      if (!refined && lenses(c, k) != given(c, k)) {
        lenses(c, k) = given(c, k);
        moved = true;
      }
    }
  }
  return moved;
}

void Problem::Gate(const Result& solution, const SelfCalibrationOptions& options) {
  const int n = static_cast<int>(camera_index.size());
  std::vector<double> error(n);
  std::vector<bool> keep(n);
  for (int i = 0; i < n; ++i) {
    error[i] = solution.residuals.row(i).norm();
    keep[i] = std::isfinite(error[i]);
  }
  for (int c = 0; c < static_cast<int>(cameras.size()); ++c) {
    std::vector<double> inliers;
    for (int i = 0; i < n; ++i) {
      if (camera_index(i) == c && keep[i]) inliers.push_back(error[i]);
    }
    const double sigma = inliers.empty() ? solution.noise_px(c) : 1.4826 * Percentile(inliers, 50.0) / std::sqrt(2.0);
    const double gate = std::max(options.outlier_gate_px, options.outlier_gate_sigma_factor * sigma);
    for (int i = 0; i < n; ++i) {
      if (camera_index(i) == c) keep[i] = keep[i] && error[i] < gate;
    }
  }
  Keep(keep);
}

// Keeps the observations `keep` selects and the points they still show twice.
void Problem::Keep(std::vector<bool> keep) {
  const int n = static_cast<int>(camera_index.size());
  std::vector<int> seen(points.rows(), 0);
  for (int i = 0; i < n; ++i) {
    if (keep[i]) ++seen[point_index(i)];
  }
  std::vector<int> remap(points.rows(), -1);
  std::vector<int> used;
  for (int i = 0; i < n; ++i) {
    keep[i] = keep[i] && seen[point_index(i)] >= 2;
    if (keep[i]) remap[point_index(i)] = 0;
  }
  for (int p = 0; p < static_cast<int>(points.rows()); ++p) {
    if (remap[p] == 0) {
      remap[p] = static_cast<int>(used.size());
      used.push_back(p);
    }
  }
  std::vector<int> rows;
  for (int i = 0; i < n; ++i) {
    if (keep[i]) rows.push_back(i);
  }
  Eigen::VectorXi cameras_kept(rows.size()), points_kept(rows.size());
  ba::PixelMatrix observed_kept(rows.size(), 2);
  for (size_t k = 0; k < rows.size(); ++k) {
    cameras_kept(k) = camera_index(rows[k]);
    points_kept(k) = remap[point_index(rows[k])];
    observed_kept.row(k) = observed.row(rows[k]);
  }
  FloorMatrix points_used(used.size(), 2);
  for (size_t k = 0; k < used.size(); ++k) points_used.row(k) = points.row(used[k]);
  camera_index = cameras_kept;
  point_index = points_kept;
  observed = observed_kept;
  points = points_used;
}

namespace {

template <typename Matrix>
Matrix WithoutRow(const Matrix& matrix, int row) {
  Matrix out(matrix.rows() - 1, matrix.cols());
  out.topRows(row) = matrix.topRows(row);
  out.bottomRows(matrix.rows() - row - 1) = matrix.bottomRows(matrix.rows() - row - 1);
  return out;
}

}  // namespace

void Problem::DropCamera(int c) {
  dropped.emplace_back(cameras[c], CountOf(c));
  std::vector<bool> keep(camera_index.size());
  for (int i = 0; i < camera_index.size(); ++i) {
    keep[i] = camera_index(i) != c;
    if (camera_index(i) > c) --camera_index(i);
  }
  Keep(keep);
  cameras.erase(cameras.begin() + c);
  refine.erase(refine.begin() + c);
  requested.erase(requested.begin() + c);
  image_sizes.erase(image_sizes.begin() + c);
  shapes.erase(shapes.begin() + c);
  given = WithoutRow(given, c);
  start = WithoutRow(start, c);
  lenses = WithoutRow(lenses, c);
  poses = WithoutRow(poses, c);
}

double Problem::Coverage(int camera) const {
  const Eigen::Vector2d centre(lenses(camera, kCx), lenses(camera, kCy));
  const auto [width, height] = image_sizes[camera];
  double corner = 0.0;
  for (const Eigen::Vector2d& p : {Eigen::Vector2d(0.0, 0.0), Eigen::Vector2d(width - 1, 0.0),
                                   Eigen::Vector2d(0.0, height - 1), Eigen::Vector2d(width - 1, height - 1)}) {
    corner = std::max(corner, (p - centre).norm());
  }
  std::vector<double> radius;
  for (const int i : RowsOfCamera(camera_index, camera)) radius.push_back((observed.row(i).transpose() - centre).norm());
  return radius.empty() ? 0.0 : Percentile(radius, 95.0) / corner;
}

std::optional<SystematicResidual> Problem::Systematic(int camera, const Result& solution) const {
  constexpr int kTerms = 6;  // 1, u, v, u^2, uv, v^2 per axis
  std::vector<int> rows;
  for (const int i : RowsOfCamera(camera_index, camera)) {
    if (solution.residuals.row(i).allFinite()) rows.push_back(i);
  }
  const int n = static_cast<int>(rows.size());
  if (n < 4 * kTerms) return std::nullopt;
  const auto [width, height] = image_sizes[camera];
  Eigen::MatrixXd basis(n, kTerms);
  Eigen::MatrixXd residuals(n, 2);
  for (int k = 0; k < n; ++k) {
    // Coordinates in [-1, 1] across the image keep the basis well conditioned.
    const double u = 2.0 * observed(rows[k], 0) / width - 1.0, v = 2.0 * observed(rows[k], 1) / height - 1.0;
    basis.row(k) << 1.0, u, v, u * u, u * v, v * v;
    residuals.row(k) = solution.residuals.row(rows[k]);
  }
  const Eigen::MatrixXd field = basis * basis.colPivHouseholderQr().solve(residuals);
  const double left = (residuals - field).squaredNorm();
  const double variance = left / std::max(1, 2 * n - 2 * kTerms);
  if (!(variance > 0.0)) return std::nullopt;
  return SystematicResidual{std::sqrt(field.squaredNorm() / n), (residuals.squaredNorm() - left) / variance};
}

std::vector<Eigen::Vector2d> Problem::Seen(int camera, int count) const {
  const std::vector<int> rows = RowsOfCamera(camera_index, camera);
  const size_t step = std::max<size_t>(1, rows.size() / static_cast<size_t>(count));
  const Eigen::Matrix3d R = Rotation(poses.row(camera).head<3>().transpose());
  const Eigen::Vector3d t = poses.row(camera).tail<3>().transpose();
  std::vector<Eigen::Vector2d> out;
  for (size_t k = 0; k < rows.size(); k += step) {
    const Eigen::Vector3d p = R.leftCols<2>() * points.row(point_index(rows[k])).transpose() + t;
    out.emplace_back(p(0) / p(2), p(1) / p(2));
  }
  return out;
}

std::vector<std::vector<int>> Problem::StageEntries(const std::vector<std::string>& stage,
                                                    const std::vector<std::vector<int>>& before,
                                                    const std::set<int>& rejected) const {
  std::vector<std::vector<int>> out;
  for (size_t c = 0; c < before.size(); ++c) {
    std::set<int> entries(before[c].begin(), before[c].end());
    if (!rejected.count(static_cast<int>(c))) {
      for (const std::string& name : stage) {
        if (Contains(requested[c], name)) {
          for (const int k : RefinableOf(name).indices) entries.insert(k);
        }
      }
    }
    out.emplace_back(entries.begin(), entries.end());
  }
  return out;
}

namespace {

double SquaredSum(const ba::PixelMatrix& residuals, const std::vector<int>& rows) {
  double sum = 0.0;
  for (const int i : rows) {
    for (int axis = 0; axis < 2; ++axis) {
      if (!std::isnan(residuals(i, axis))) sum += residuals(i, axis) * residuals(i, axis);
    }
  }
  return sum;
}

}  // namespace

std::string Problem::Insignificant(int c, const Result& before, const Result& after, int added,
                                   const SelfCalibrationOptions& options) const {
  const std::vector<int> rows = RowsOfCamera(camera_index, c);
  const double variance = after.noise_px(c) * after.noise_px(c);
  const double drop = (SquaredSum(before.residuals, rows) - SquaredSum(after.residuals, rows)) / variance;
  if (drop >= options.min_chi2_drop * added) return "";
  return "does not improve the fit: the residuals fell by " + FormatNumber("%.1f", std::max(drop, 0.0)) +
         " noise variances, less than " + FormatNumber("%g", options.min_chi2_drop) + " per entry";
}

}  // namespace calibproj::selfcal
