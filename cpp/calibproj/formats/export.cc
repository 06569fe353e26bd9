#include "calibproj/formats/export.h"

#include <Eigen/Geometry>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <unordered_map>

#include "calibproj/formats/files.h"

namespace calibproj::formats {

namespace fs = std::filesystem;

const std::vector<std::string> kExportFormats = {"yaml", "colmap", "anipose"};

namespace {

constexpr char kYamlFile[] = "calibration_opencv.yaml";
constexpr char kYamlSchema[] = "calibproj.opencv_calibration/1";
constexpr char kColmapDir[] = "colmap";
constexpr char kAniposeFile[] = "calibration.toml";
// OpenCV puts pixel (0, 0) at the centre of the top-left pixel; COLMAP at (0.5, 0.5).
constexpr double kColmapPixelShift = 0.5;
// Colour given to every point in points3D.txt (the points carry no colour).
constexpr char kColmapPointRgb[] = "200 200 200";

bool IsFormat(const std::string& name) {
  for (const auto& format : kExportFormats) {
    if (format == name) return true;
  }
  return false;
}

std::string FormatList() {
  std::string out;
  for (const auto& format : kExportFormats) out += (out.empty() ? "" : ", ") + format;
  return out;
}

// Image size, or twice the principal point (rounded half to even, as Python's round).
std::pair<int, int> ImageSize(const CameraIntrinsics& camera, std::vector<std::string>* warnings) {
  if (camera.has_resolution) return {static_cast<int>(camera.width), static_cast<int>(camera.height)};
  if (warnings) {
    warnings->push_back("camera " + camera.name + ": no image size in its intrinsics; using twice the principal point");
  }
  return {static_cast<int>(std::nearbyint(camera.ImageWidth())), static_cast<int>(std::nearbyint(camera.ImageHeight()))};
}

Eigen::Vector3d Rodrigues(const Eigen::Matrix3d& R) {
  cv::Mat matrix, vector;
  cv::eigen2cv(R, matrix);
  cv::Rodrigues(matrix, vector);
  return {vector.at<double>(0), vector.at<double>(1), vector.at<double>(2)};
}

cv::Mat Column(const Eigen::Vector3d& v) { return (cv::Mat_<double>(3, 1) << v.x(), v.y(), v.z()); }

// How well a registered camera is known, as the results say it: its status (the first
// registered camera is the reference the others' sigmas are relative to), its 1-sigma
// rotation (deg) and centre (the calibration's unit), and its mean reprojection error.
struct Quality {
  std::string status = "ok";  // reference, ok or weak
  std::optional<double> rotation_sigma_deg, centre_sigma, mean_px;
};

Quality QualityOf(const Calibration& calibration, const std::string& name) {
  Quality quality;
  for (const auto& [camera, metrics] : calibration.metrics) {
    if (camera != name) continue;
    quality.status = metrics.weak ? "weak" : "ok";
    quality.rotation_sigma_deg = metrics.rotation_sigma_deg;
    quality.centre_sigma = metrics.centre_sigma;
    quality.mean_px = metrics.mean_px;
  }
  if (!calibration.registration_order.empty() && calibration.registration_order.front() == name) {
    quality = Quality{"reference", std::nullopt, std::nullopt, quality.mean_px};
  }
  return quality;
}

// "far2 ok: rotation 0.0037 deg, centre 0.00114 m (1 sigma), mean error 0.026 px".
std::string QualityLine(const Calibration& calibration, const std::string& name) {
  const Quality quality = QualityOf(calibration, name);
  std::string line = name + " " + quality.status;
  if (quality.rotation_sigma_deg && quality.centre_sigma) {
    line += ": rotation " + FormatNumber("%.3g", *quality.rotation_sigma_deg) + " deg, centre " +
            FormatNumber("%.3g", *quality.centre_sigma) + " " + (calibration.unit == "m" ? "m" : "units") +
            " (1 sigma, relative to the reference)";
  }
  if (quality.mean_px) line += (quality.rotation_sigma_deg ? ", mean error " : ": mean error ") +
                               FormatNumber("%.3g", *quality.mean_px) + " px";
  return line;
}

// -- OpenCV YAML --------------------------------------------------------------------------

std::vector<fs::path> WriteOpenCvYaml(const Calibration& calibration, const fs::path& directory,
                                      const std::map<std::string, CameraIntrinsics>& intrinsics,
                                      std::vector<std::string>* warnings) {
  cv::FileStorage storage(kYamlFile, cv::FileStorage::WRITE | cv::FileStorage::MEMORY);
  storage << "schema" << kYamlSchema << "unit" << calibration.unit << "frame" << "floor";
  storage << "pose_convention" << "x_cam = R * X_world + t";
  storage << "camera_count" << static_cast<int>(calibration.poses.size());
  storage << "cameras" << "[";
  for (const auto& pose : calibration.poses) {
    const CameraIntrinsics& camera = intrinsics.at(pose.name);
    const auto [width, height] = ImageSize(camera, warnings);
    cv::Mat K, R;
    cv::eigen2cv(camera.K, K);
    cv::eigen2cv(pose.R, R);
    storage << "{" << "name" << pose.name << "image_width" << width << "image_height" << height;
    storage << "camera_matrix" << K << "distortion_coefficients" << cv::Mat(camera.dist, true).reshape(1, 1);
    storage << "R" << R << "t" << Column(pose.t) << "rvec" << Column(Rodrigues(pose.R));
    const Quality quality = QualityOf(calibration, pose.name);
    storage << "status" << quality.status;  // reference, ok or weak
    if (quality.rotation_sigma_deg) storage << "rotation_sigma_deg" << *quality.rotation_sigma_deg;
    if (quality.centre_sigma) storage << "centre_sigma" << *quality.centre_sigma;
    if (quality.mean_px) storage << "mean_error_px" << *quality.mean_px;
    storage << "}";
  }
  storage << "]";
  const fs::path path = directory / kYamlFile;
  AtomicWrite(path, storage.releaseAndGetString());
  return {path};
}

// -- COLMAP text model --------------------------------------------------------------------

// A camera's observations of reconstructed points in front of it.
struct ColmapObservations {
  std::vector<std::int64_t> ids;
  std::vector<Eigen::Vector2d> pixels;  // distorted, COLMAP's pixel convention
  std::vector<double> errors;           // reprojection error, undistorted pixels
};

Eigen::Vector2d Distorted(const CameraIntrinsics& camera, const Eigen::Vector2d& pixel) {
  bool distortion = false;
  for (double d : camera.dist) distortion |= d != 0.0;
  if (!distortion) return pixel;
  const cv::Point3d normalised((pixel.x() - camera.K(0, 2)) / camera.K(0, 0),
                               (pixel.y() - camera.K(1, 2)) / camera.K(1, 1), 1.0);
  std::vector<cv::Point2d> projected;
  const cv::Mat zero = cv::Mat::zeros(3, 1, CV_64F);
  cv::projectPoints(std::vector<cv::Point3d>{normalised}, zero, zero, cv::Mat::eye(3, 3, CV_64F),
                    cv::Mat(camera.dist, true), projected);
  const Eigen::Vector2d xy(projected[0].x, projected[0].y);
  return camera.K.topLeftCorner<2, 2>() * xy + camera.K.topRightCorner<2, 1>();
}

std::map<std::string, ColmapObservations> ObservationsOf(const Calibration& calibration, const Tracks* tracks,
                                                         const std::map<std::string, CameraIntrinsics>& intrinsics) {
  std::map<std::string, ColmapObservations> out;
  if (tracks == nullptr) return out;
  std::unordered_map<std::int64_t, Eigen::Index> row_of;
  for (size_t p = 0; p < calibration.point_ids.size(); ++p) row_of[calibration.point_ids[p]] = p;
  for (const auto& pose : calibration.poses) {
    const auto camera_it = std::find(tracks->cameras.begin(), tracks->cameras.end(), pose.name);
    if (camera_it == tracks->cameras.end()) continue;
    const int c = static_cast<int>(camera_it - tracks->cameras.begin());
    const CameraIntrinsics& camera = intrinsics.at(pose.name);
    ColmapObservations& observations = out[pose.name];
    for (Eigen::Index i = 0; i < tracks->camera_index.size(); ++i) {
      if (tracks->camera_index[i] != c) continue;
      const std::int64_t id = tracks->point_ids[tracks->point_index[i]];
      const auto row = row_of.find(id);
      if (row == row_of.end()) continue;
      const Eigen::Vector3d in_camera = pose.R * calibration.points.row(row->second).transpose() + pose.t;
      if (!(in_camera.z() > 0)) continue;
      const Eigen::Vector2d projected =
          camera.K.topLeftCorner<2, 2>() * in_camera.head<2>() / in_camera.z() + camera.K.topRightCorner<2, 1>();
      const Eigen::Vector2d xy = tracks->xy.row(i).transpose();
      observations.ids.push_back(id);
      observations.pixels.push_back(Distorted(camera, xy) + Eigen::Vector2d::Constant(kColmapPixelShift));
      observations.errors.push_back((projected - xy).norm());
    }
  }
  return out;
}

std::string Numbers(const std::vector<double>& values) {
  std::string out;
  for (double value : values) out += (out.empty() ? "" : " ") + PythonFloat(value);
  return out;
}

std::string ColmapCamerasText(const Calibration& calibration,
                              const std::map<std::string, CameraIntrinsics>& intrinsics,
                              std::vector<std::string>* warnings) {
  std::string text = "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
                     "# Number of cameras: " + std::to_string(calibration.poses.size()) + "\n";
  // COLMAP skips comment lines: how well each camera is known goes here.
  int quality_id = 1;
  for (const auto& pose : calibration.poses) {
    text += "# calibproj camera " + std::to_string(quality_id++) + ": " + QualityLine(calibration, pose.name) + "\n";
  }
  int camera_id = 1;
  for (const auto& pose : calibration.poses) {
    const CameraIntrinsics& camera = intrinsics.at(pose.name);
    const auto [model, params] = ColmapCamera(camera);
    const auto [width, height] = ImageSize(camera, warnings);
    text += std::to_string(camera_id++) + " " + model + " " + std::to_string(width) + " " + std::to_string(height) +
            " " + Numbers(params) + "\n";
  }
  return text;
}

std::string ColmapImagesText(const Calibration& calibration,
                             const std::map<std::string, ColmapObservations>& observations) {
  size_t count = 0;
  for (const auto& [name, seen] : observations) count += seen.ids.size();
  const size_t images = calibration.poses.size();
  std::string text = "# Image list with two lines of data per image:\n"
                     "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
                     "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
                     "# Number of images: " + std::to_string(images) + ", mean observations per image: " +
                     FormatNumber("%g", static_cast<double>(count) / images) + "\n";
  int image_id = 1;
  for (const auto& pose : calibration.poses) {
    const Eigen::Vector4d q = QuaternionWxyz(pose.R);
    const std::string id = std::to_string(image_id++);
    text += id + " " + Numbers({q[0], q[1], q[2], q[3], pose.t.x(), pose.t.y(), pose.t.z()}) + " " + id + " " +
            pose.name + "\n";
    std::string points;
    const auto seen = observations.find(pose.name);
    if (seen != observations.end()) {
      for (size_t k = 0; k < seen->second.ids.size(); ++k) {
        const Eigen::Vector2d& pixel = seen->second.pixels[k];
        points += (points.empty() ? "" : " ") + PythonFloat(pixel.x()) + " " + PythonFloat(pixel.y()) + " " +
                  std::to_string(seen->second.ids[k]);
      }
    }
    text += points + "\n";
  }
  return text;
}

std::string ColmapPointsText(const Calibration& calibration,
                             const std::map<std::string, ColmapObservations>& observations) {
  std::unordered_map<std::int64_t, std::vector<std::pair<int, size_t>>> tracks;
  std::unordered_map<std::int64_t, std::vector<double>> errors;
  int image_id = 1;
  for (const auto& pose : calibration.poses) {
    const auto seen = observations.find(pose.name);
    if (seen != observations.end()) {
      for (size_t k = 0; k < seen->second.ids.size(); ++k) {
        tracks[seen->second.ids[k]].emplace_back(image_id, k);
        errors[seen->second.ids[k]].push_back(seen->second.errors[k]);
      }
    }
    ++image_id;
  }
  const size_t points = calibration.point_ids.size();
  size_t track_sum = 0;
  for (const auto& [id, track] : tracks) track_sum += track.size();
  std::string text = "# 3D point list with one line of data per point:\n"
                     "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
                     "# Number of points: " + std::to_string(points) + ", mean track length: " +
                     FormatNumber("%g", points ? static_cast<double>(track_sum) / points : 0.0) + "\n";
  for (size_t p = 0; p < points; ++p) {
    const std::int64_t id = calibration.point_ids[p];
    double error = 0.0;
    std::string track;
    if (const auto e = errors.find(id); e != errors.end()) {
      for (double value : e->second) error += value;
      error /= e->second.size();
      for (const auto& [image, index] : tracks[id]) {
        track += (track.empty() ? "" : " ") + std::to_string(image) + " " + std::to_string(index);
      }
    }
    const Eigen::RowVector3d xyz = calibration.points.row(p);
    text += std::to_string(id) + " " + Numbers({xyz.x(), xyz.y(), xyz.z()}) + " " + kColmapPointRgb + " " +
            PythonFloat(error) + (track.empty() ? "" : " " + track) + "\n";
  }
  return text;
}

std::vector<fs::path> WriteColmap(const Calibration& calibration, const fs::path& directory,
                                  const std::map<std::string, CameraIntrinsics>& intrinsics, const Tracks* tracks,
                                  std::vector<std::string>* warnings) {
  const fs::path folder = directory / kColmapDir;
  const auto observations = ObservationsOf(calibration, tracks, intrinsics);
  const std::vector<fs::path> files = {folder / "cameras.txt", folder / "images.txt", folder / "points3D.txt"};
  AtomicWrite(files[0], ColmapCamerasText(calibration, intrinsics, warnings));
  AtomicWrite(files[1], ColmapImagesText(calibration, observations));
  AtomicWrite(files[2], ColmapPointsText(calibration, observations));
  return files;
}

// -- aniposelib calibration.toml ----------------------------------------------------------

// A TOML basic string: JSON's escapes are TOML's, and DEL must be escaped too.
std::string TomlString(const std::string& text) {
  std::string quoted = nlohmann::json(text).dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  std::string out;
  for (char c : quoted) out += c == '\x7f' ? std::string("\\u007f") : std::string(1, c);
  return out;
}

std::string TomlNumbers(const std::vector<double>& values) {
  std::string out = "[";
  for (size_t k = 0; k < values.size(); ++k) out += (k ? ", " : "") + PythonFloat(values[k]);
  return out + "]";
}

// Mean reprojection error of the inlier observations, pixels.
double MeanError(const Calibration& calibration) {
  double sum = 0.0, count = 0.0;
  for (const auto& [name, metrics] : calibration.metrics) {
    if (!metrics.mean_px || metrics.inliers == 0) continue;
    sum += *metrics.mean_px * metrics.inliers;
    count += metrics.inliers;
  }
  return count > 0 ? sum / count : 0.0;
}

std::vector<fs::path> WriteAniposeToml(const Calibration& calibration, const fs::path& directory,
                                       const std::map<std::string, CameraIntrinsics>& intrinsics,
                                       std::vector<std::string>* warnings) {
  std::string text;
  int index = 0;
  for (const auto& pose : calibration.poses) {
    const CameraIntrinsics& camera = intrinsics.at(pose.name);
    const auto [width, height] = ImageSize(camera, warnings);
    std::string matrix = "[";
    for (int row = 0; row < 3; ++row) {
      matrix += (row ? ", " : "") + TomlNumbers({camera.K(row, 0), camera.K(row, 1), camera.K(row, 2)});
    }
    const Eigen::Vector3d rotation = Rodrigues(pose.R);
    text += "[cam_" + std::to_string(index++) + "]\n";
    text += "name = " + TomlString(pose.name) + "\n";
    text += "size = [" + std::to_string(width) + ", " + std::to_string(height) + "]\n";
    text += "matrix = " + matrix + "]\n";
    text += "distortions = " + TomlNumbers(camera.dist) + "\n";
    text += "rotation = " + TomlNumbers({rotation.x(), rotation.y(), rotation.z()}) + "\n";
    text += "translation = " + TomlNumbers({pose.t.x(), pose.t.y(), pose.t.z()}) + "\n";
    // aniposelib reads the keys above; these say how well the camera is known.
    const Quality quality = QualityOf(calibration, pose.name);
    text += "status = " + TomlString(quality.status) + "\n";
    if (quality.rotation_sigma_deg) text += "rotation_sigma_deg = " + PythonFloat(*quality.rotation_sigma_deg) + "\n";
    if (quality.centre_sigma) text += "centre_sigma = " + PythonFloat(*quality.centre_sigma) + "\n";
    text += "\n";
  }
  text += "[metadata]\nadjusted = true\n";  // the poses come out of a bundle adjustment
  text += "error = " + PythonFloat(MeanError(calibration)) + "\n";
  text += "unit = " + TomlString(calibration.unit) + "\nframe = \"floor\"\nsource = \"calibproj\"\n";
  const fs::path path = directory / kAniposeFile;
  AtomicWrite(path, text);
  return {path};
}

}  // namespace

std::vector<std::string> ParseExportFormats(const std::string& text) {
  std::vector<std::string> formats;
  std::string unknown;
  size_t start = 0;
  for (size_t comma = text.find(','); ; comma = text.find(',', start)) {
    const std::string part =
        Trimmed(text.substr(start, comma == std::string::npos ? std::string::npos : comma - start));
    if (!part.empty()) {
      if (!IsFormat(part) && unknown.empty()) unknown = part;
      if (std::find(formats.begin(), formats.end(), part) == formats.end()) formats.push_back(part);
    }
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  if (!unknown.empty() || formats.empty()) {
    throw std::invalid_argument("export format " + PythonRepr(unknown.empty() ? text : unknown) +
                                " unknown (expected a comma-separated list of " + FormatList() + ")");
  }
  return formats;
}

std::vector<fs::path> Export(const Calibration& calibration, const std::string& format, const fs::path& directory,
                             const std::map<std::string, CameraIntrinsics>& intrinsics, const Tracks* tracks,
                             std::vector<std::string>* warnings) {
  if (!IsFormat(format)) {
    throw std::invalid_argument("export format " + PythonRepr(format) + " unknown (expected one of " + FormatList() +
                                ")");
  }
  calibration.Check();
  if (tracks) tracks->Check();
  std::string missing;
  for (const auto& pose : calibration.poses) {
    if (!intrinsics.count(pose.name)) missing += (missing.empty() ? "" : ", ") + pose.name;
  }
  if (!missing.empty()) throw std::invalid_argument("no intrinsics for registered camera(s) " + missing);
  if (calibration.poses.empty()) throw std::invalid_argument("no registered camera to export");
  if (format == "yaml") return WriteOpenCvYaml(calibration, directory, intrinsics, warnings);
  if (format == "colmap") return WriteColmap(calibration, directory, intrinsics, tracks, warnings);
  return WriteAniposeToml(calibration, directory, intrinsics, warnings);
}

// COLMAP model and parameters: PINHOLE without distortion, OPENCV with k1, k2, p1, p2,
// FULL_OPENCV with k3 or the rational terms; thin-prism and tilt terms have no model.
std::pair<std::string, std::vector<double>> ColmapCamera(const CameraIntrinsics& camera) {
  std::vector<double> dist(std::max<size_t>(8, camera.dist.size()), 0.0);
  std::copy(camera.dist.begin(), camera.dist.end(), dist.begin());
  const auto any_beyond = [&dist](size_t first) {
    for (size_t k = first; k < dist.size(); ++k) {
      if (dist[k] != 0.0) return true;
    }
    return false;
  };
  if (any_beyond(8)) {
    throw std::invalid_argument("camera " + camera.name + ": thin-prism or tilt distortion has no COLMAP camera model");
  }
  std::vector<double> params = {camera.K(0, 0), camera.K(1, 1), camera.K(0, 2) + kColmapPixelShift,
                                camera.K(1, 2) + kColmapPixelShift};
  if (!any_beyond(0)) return {"PINHOLE", params};
  const size_t terms = any_beyond(4) ? 8 : 4;
  params.insert(params.end(), dist.begin(), dist.begin() + terms);
  return {terms == 8 ? "FULL_OPENCV" : "OPENCV", params};
}

// Unit quaternion (w, x, y, z) of a rotation, w >= 0.
Eigen::Vector4d QuaternionWxyz(const Eigen::Matrix3d& R) {
  Eigen::Quaterniond q(R);
  q.normalize();
  Eigen::Vector4d wxyz(q.w(), q.x(), q.y(), q.z());
  return q.w() < 0 ? Eigen::Vector4d(-wxyz) : wxyz;
}

}  // namespace calibproj::formats
