#pragma once
// What a calibration's uncertainty means for the user's points: the expected error of a
// point triangulated from the cameras that see it, and how far a point of the room may
// project from where the calibration puts it in each camera's image.
//
// A point X seen by cameras c (in front, inside the image) is triangulated by weighted
// least squares from their pixels u_c. To first order
//   dX = H^-1 sum_c J_c^T W_c (du_c - P_c dpose_c),  H = sum_c J_c^T W_c J_c,
// with J_c = d pixel / d X and P_c = d pixel / d pose_c. Each camera is weighed by how
// well it places the point, W_c = (sigma_c^2 I + P_c Sigma_cc P_c^T)^-1 (its pixels'
// noise sigma_c and its own pose's uncertainty there), so that a camera whose pose is
// poorly known (a zoomed one, relative to the reference) does not drag the point. The
// covariance is H^-1 (sum_c sigma_c^2 J_c^T W_c W_c J_c + G Sigma G^T) H^-1, with G the
// blocks J_c^T W_c P_c side by side and Sigma the poses' joint covariance: the cross
// terms between cameras enter (two cameras whose poses err together err less relative
// to each other). The gauge is the calibration's: the reference camera's pose and its
// distance to the floor held.
//
// A camera whose intrinsics were refined (--refine-intrinsics) has its lens in the joint
// covariance too (registration::PoseUncertainty): P_c then also holds the pixel's
// derivative by the lens (selfcal::ResidualByLens), and its cross terms with the poses
// enter as the poses' do.

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "calibproj/formats/calibration.h"
#include "calibproj/formats/intrinsics_file.h"
#include "calibproj/selfcal/lens.h"

namespace calibproj::uncertainty {

struct PointUncertainty {
  bool determined = false;          // seen by two cameras at least, not along one line
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // calibration unit squared
  Eigen::Matrix3d from_poses = Eigen::Matrix3d::Zero();  // the calibration's share of it (poses, lenses)
  std::vector<int> cameras;         // indices into the model's cameras

  // 1 sigma along the worst direction.
  double WorstSigma() const;
};

class UncertaintyModel {
 public:
  // The calibration's registered cameras that have intrinsics and a pose covariance.
  // std::invalid_argument when the calibration carries no pose uncertainty, or a camera
  // of it has no pose or no intrinsics.
  UncertaintyModel(const formats::Calibration& calibration,
                   const std::map<std::string, formats::CameraIntrinsics>& intrinsics);

  int num_cameras() const { return static_cast<int>(cameras_.size()); }
  const std::string& name(int camera) const { return cameras_[camera].name; }
  double noise_px(int camera) const { return cameras_[camera].noise_px; }
  const std::string& reference() const { return reference_; }

  // Whether the camera sees X: in front, and its distorted pixel inside the image.
  bool Sees(int camera, const Eigen::Vector3d& X) const;
  // Triangulation from the cameras that see X; `noise_px` > 0 replaces every camera's
  // noise for the new pixels (the user's detector), else each camera's own.
  PointUncertainty Triangulation(const Eigen::Vector3d& X, double noise_px = 0.0) const;
  // Covariance (px^2) of X's pixel in the camera from the calibration's uncertainty
  // alone: its pose's, and its lens's where refined.
  Eigen::Matrix2d Projection(int camera, const Eigen::Vector3d& X) const;

 private:
  struct Camera {
    std::string name;
    std::vector<int> parameters;  // its rows of the joint covariance: pose, then lens
    bool refined_lens = false;
    double lens_block[8] = {};  // [f, cx, cy, k1, k2, p1, p2, k3] when refined
    selfcal::LensShape shape;
    Eigen::Matrix3d K;
    Eigen::Matrix3d R;
    Eigen::Vector3d t;
    formats::CameraIntrinsics lens;  // to tell whether a pixel is in the image
    double width = 0.0, height = 0.0;
    double noise_px = 1.0;
  };
  // Pixel of X and its derivatives by X and by the camera's parameters (its pose's
  // [dtheta, dt], then its lens's entries when refined).
  void Jacobians(const Camera& camera, const Eigen::Vector3d& X, Eigen::Matrix<double, 2, 3>* by_point,
                 Eigen::Matrix<double, 2, Eigen::Dynamic>* by_parameters) const;

  // The covariance of camera a's parameters with camera b's, at [a * num_cameras() + b]:
  // taken out of the joint covariance once, not at every point.
  const Eigen::MatrixXd& Cross(int a, int b) const { return cross_[a * cameras_.size() + b]; }

  std::vector<Camera> cameras_;
  std::vector<Eigen::MatrixXd> cross_;
  std::string reference_;
};

}  // namespace calibproj::uncertainty
