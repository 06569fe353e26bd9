#include "calibproj/uncertainty/triangulation.h"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "calibproj/ba/rotation.h"
#include "calibproj/detect/lens.h"

namespace calibproj::uncertainty {

namespace {

// A camera sees points at least this far in front of it (calibration units share of its
// height would be more exact; the views of a room never come this close).
constexpr double kMinDepth = 1e-6;
// Two rays closer than this to parallel do not determine a point.
constexpr double kMinReciprocalCondition = 1e-10;

}  // namespace

double PointUncertainty::WorstSigma() const {
  if (!determined) return std::numeric_limits<double>::quiet_NaN();
  const double largest = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(covariance).eigenvalues().maxCoeff();
  return std::sqrt(std::max(0.0, largest));
}

UncertaintyModel::UncertaintyModel(const formats::Calibration& calibration,
                                   const std::map<std::string, formats::CameraIntrinsics>& intrinsics) {
  const registration::PoseUncertainty& poses = calibration.uncertainty;
  if (poses.empty()) {
    throw std::invalid_argument("the calibration has no pose covariance (its final bundle adjustment gave none)");
  }
  poses.Check();
  reference_ = poses.reference;
  for (size_t k = 0; k < poses.cameras.size(); ++k) {
    const std::string& name = poses.cameras[k];
    const formats::CameraPose* pose = calibration.PoseOf(name);
    if (pose == nullptr) throw std::invalid_argument("pose covariance: camera " + name + " has no pose");
    const auto lens = intrinsics.find(name);
    if (lens == intrinsics.end()) throw std::invalid_argument("camera " + name + ": no intrinsics");
    Camera camera;
    camera.name = name;
    camera.parameters = poses.ParametersOf(static_cast<int>(k));
    camera.refined_lens = camera.parameters.size() > 6;
    const std::vector<double>& dist = lens->second.dist;
    selfcal::LensOf(lens->second.K, dist.data(), static_cast<int>(dist.size()), camera.lens_block, &camera.shape);
    camera.K = lens->second.K;
    camera.R = pose->R;
    camera.t = pose->t;
    camera.lens = lens->second;
    camera.width = lens->second.ImageWidth();
    camera.height = lens->second.ImageHeight();
    camera.noise_px = poses.noise_px[k];
    cameras_.push_back(std::move(camera));
  }
  for (const Camera& a : cameras_) {
    for (const Camera& b : cameras_) cross_.push_back(poses.covariance(a.parameters, b.parameters));
  }
}

bool UncertaintyModel::Sees(int index, const Eigen::Vector3d& X) const {
  const Camera& camera = cameras_[index];
  const Eigen::Vector3d x = camera.R * X + camera.t;
  if (!(x.z() > kMinDepth)) return false;
  const Eigen::Vector3d pixel = camera.K * (x / x.z());
  // A wide lens's distortion model folds back far outside its image: only undistorted
  // pixels near the image are mapped through it.
  const double margin = 0.5 * std::max(camera.width, camera.height);
  if (pixel.x() < -margin || pixel.y() < -margin || pixel.x() > camera.width + margin ||
      pixel.y() > camera.height + margin) {
    return false;
  }
  const cv::Point2d distorted =
      camera.lens.HasDistortion() ? detect::DistortPixels(camera.lens, {cv::Point2d(pixel.x(), pixel.y())})[0]
                                  : cv::Point2d(pixel.x(), pixel.y());
  return distorted.x >= 0.0 && distorted.y >= 0.0 && distorted.x <= camera.width - 1.0 &&
         distorted.y <= camera.height - 1.0;
}

void UncertaintyModel::Jacobians(const Camera& camera, const Eigen::Vector3d& X, Eigen::Matrix<double, 2, 3>* by_point,
                                 Eigen::Matrix<double, 2, Eigen::Dynamic>* by_parameters) const {
  const Eigen::Vector3d x = camera.R * X + camera.t;
  // Pinhole pixel u = K [x/z, y/z, 1]: du/dx through the normalised coordinates.
  Eigen::Matrix<double, 2, 3> projection;
  projection << 1.0 / x.z(), 0.0, -x.x() / (x.z() * x.z()), 0.0, 1.0 / x.z(), -x.y() / (x.z() * x.z());
  const Eigen::Matrix<double, 2, 3> by_camera_point = camera.K.topLeftCorner<2, 2>() * projection;
  *by_point = by_camera_point * camera.R;
  // R = Exp(dtheta) R_hat moves x by dtheta x (R_hat X); t by dt.
  by_parameters->resize(2, static_cast<Eigen::Index>(camera.parameters.size()));
  by_parameters->leftCols<3>() = -by_camera_point * ba::Skew(camera.R * X);
  by_parameters->middleCols<3>(3) = by_camera_point;
  if (camera.refined_lens) {
    by_parameters->rightCols<8>() =
        selfcal::ResidualByLens(camera.lens_block, camera.shape, Eigen::Vector2d(x.x() / x.z(), x.y() / x.z()));
  }
}

PointUncertainty UncertaintyModel::Triangulation(const Eigen::Vector3d& X, double noise_px) const {
  PointUncertainty out;
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero(), pixel_part = Eigen::Matrix3d::Zero();
  std::vector<Eigen::Matrix<double, 3, Eigen::Dynamic>> G;
  for (int c = 0; c < num_cameras(); ++c) {
    if (!Sees(c, X)) continue;
    Eigen::Matrix<double, 2, 3> J;
    Eigen::Matrix<double, 2, Eigen::Dynamic> P;
    Jacobians(cameras_[c], X, &J, &P);
    const double sigma = noise_px > 0.0 ? noise_px : cameras_[c].noise_px;
    // Each camera weighed by how well it places the point: its pixels' noise and its
    // own pose's (and lens's) uncertainty there (a camera whose pose is poorly known
    // counts less).
    const Eigen::Matrix2d own =
        sigma * sigma * Eigen::Matrix2d::Identity() + P * Cross(c, c) * P.transpose();
    const Eigen::Matrix2d W = own.inverse();
    H += J.transpose() * W * J;
    pixel_part += sigma * sigma * J.transpose() * W * W * J;
    G.push_back(J.transpose() * W * P);
    out.cameras.push_back(c);
  }
  if (out.cameras.size() < 2) return out;
  const Eigen::FullPivLU<Eigen::Matrix3d> lu(H);
  if (!lu.isInvertible() || lu.rcond() < kMinReciprocalCondition) return out;
  const Eigen::Matrix3d H_inverse = lu.inverse();
  Eigen::Matrix3d pose_part = Eigen::Matrix3d::Zero();
  for (size_t a = 0; a < out.cameras.size(); ++a) {
    for (size_t b = 0; b < out.cameras.size(); ++b) {
      pose_part += G[a] * Cross(out.cameras[a], out.cameras[b]) * G[b].transpose();
    }
  }
  out.from_poses = H_inverse * pose_part * H_inverse.transpose();
  out.covariance = H_inverse * pixel_part * H_inverse.transpose() + out.from_poses;
  out.covariance = 0.5 * (out.covariance + out.covariance.transpose());
  out.determined = out.covariance.allFinite();
  return out;
}

Eigen::Matrix2d UncertaintyModel::Projection(int camera, const Eigen::Vector3d& X) const {
  Eigen::Matrix<double, 2, 3> J;
  Eigen::Matrix<double, 2, Eigen::Dynamic> P;
  Jacobians(cameras_[camera], X, &J, &P);
  return P * Cross(camera, camera) * P.transpose();
}

}  // namespace calibproj::uncertainty
