#include "calibproj/uncertainty/volume_map.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "calibproj/formats/files.h"

namespace calibproj::uncertainty {

namespace {

using nlohmann::ordered_json;

constexpr double kVolumeHeightShare = 0.7;  // as the check's working volume
constexpr double kVolumeTopM = 2.0;
// Figures are written to this many significant digits: enough for any reading of them,
// and the file stays small.
constexpr int kDigits = 6;

double Rounded(double value) {
  if (!std::isfinite(value) || value == 0.0) return value;
  const double magnitude = std::pow(10.0, kDigits - 1 - static_cast<int>(std::floor(std::log10(std::abs(value)))));
  return std::round(value * magnitude) / magnitude;
}

ordered_json Number(double value) { return std::isfinite(value) ? ordered_json(Rounded(value)) : ordered_json(nullptr); }

ordered_json Vector(const Eigen::Vector3d& v) { return {Number(v.x()), Number(v.y()), Number(v.z())}; }

// Metres to calibration units for heights: 1 in a metric calibration.
double HeightScale(const formats::Calibration& calibration) {
  if (calibration.unit == "m") return 1.0;
  double highest = 0.0;
  for (const auto& pose : calibration.poses) highest = std::max(highest, pose.Centre().z());
  return kVolumeHeightShare * highest / kVolumeTopM;
}

std::vector<double> Centres(double low, double high, int cells) {
  std::vector<double> out;
  const double step = (high - low) / cells;
  for (int k = 0; k < cells; ++k) out.push_back(low + (k + 0.5) * step);
  return out;
}

double Percentile(std::vector<double> values, double share) {
  if (values.empty()) return std::numeric_limits<double>::quiet_NaN();
  const size_t k = std::min(values.size() - 1, static_cast<size_t>(std::floor(share * (values.size() - 1) + 0.5)));
  std::nth_element(values.begin(), values.begin() + k, values.end());
  return values[k];
}

ordered_json PointJson(const Eigen::Vector3d& X, const PointUncertainty& u, const UncertaintyModel& model) {
  ordered_json out;
  out["point"] = Vector(X);
  out["sigma"] = Number(u.WorstSigma());
  out["sigma_xyz"] = u.determined ? Vector(u.covariance.diagonal().cwiseMax(0.0).cwiseSqrt()) : ordered_json(nullptr);
  ordered_json names = ordered_json::array();
  for (int c : u.cameras) names.push_back(model.name(c));
  out["cameras"] = names;
  return out;
}

// Per camera: how far the volume's points it sees may project (1 sigma, worst axis, px).
// Which cameras see a cell, the map's triangulation has found already.
ordered_json CameraJson(const UncertaintyModel& model, const VolumeMap& map, int camera) {
  std::vector<double> sigmas;
  for (size_t level = 0; level < map.zs.size(); ++level) {
    for (size_t row = 0; row < map.ys.size(); ++row) {
      for (size_t column = 0; column < map.xs.size(); ++column) {
        const std::vector<int>& seen = map.At(level, row, column).cameras;
        if (std::find(seen.begin(), seen.end(), camera) == seen.end()) continue;
        const Eigen::Vector3d X(map.xs[column], map.ys[row], map.zs[level]);
        const double largest =
            Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(model.Projection(camera, X)).eigenvalues().maxCoeff();
        sigmas.push_back(std::sqrt(std::max(0.0, largest)));
      }
    }
  }
  ordered_json out;
  out["name"] = model.name(camera);
  out["noise_px"] = Number(model.noise_px(camera));
  out["cells_seen"] = sigmas.size();
  out["projection_sigma_px"] = {{"median", Number(Percentile(sigmas, 0.5))},
                                {"max", Number(sigmas.empty() ? std::nan("") : *std::max_element(sigmas.begin(), sigmas.end()))}};
  return out;
}

ordered_json MapJson(const VolumeMap& map) {
  ordered_json sigma = ordered_json::array(), seen = ordered_json::array();
  for (size_t level = 0; level < map.zs.size(); ++level) {
    ordered_json sigma_rows = ordered_json::array(), seen_rows = ordered_json::array();
    for (size_t row = 0; row < map.ys.size(); ++row) {
      ordered_json sigma_row = ordered_json::array(), seen_row = ordered_json::array();
      for (size_t column = 0; column < map.xs.size(); ++column) {
        const PointUncertainty& u = map.At(level, row, column);
        sigma_row.push_back(Number(u.WorstSigma()));
        seen_row.push_back(u.cameras);
      }
      sigma_rows.push_back(sigma_row);
      seen_rows.push_back(seen_row);
    }
    sigma.push_back(sigma_rows);
    seen.push_back(seen_rows);
  }
  ordered_json out;
  const auto numbers = [](const std::vector<double>& values) {
    ordered_json array = ordered_json::array();
    for (double v : values) array.push_back(Number(v));
    return array;
  };
  out["x"] = numbers(map.xs);
  out["y"] = numbers(map.ys);
  out["z"] = numbers(map.zs);
  out["sigma"] = sigma;
  out["seen_by"] = seen;
  return out;
}

// How the figures take the intrinsics: the refined lenses (or re-zoomed: the check's
// repair) with their uncertainty and its cross terms with the poses, the others as exact.
std::string IntrinsicsNote(const registration::PoseUncertainty& poses) {
  std::string refined;
  for (size_t k = 0; k < poses.lens_block.size(); ++k) {
    if (poses.lens_block[k] >= 0) refined += (refined.empty() ? "" : ", ") + poses.cameras[k];
  }
  if (refined.empty()) return "taken as exact: their own uncertainty (refined or from a board) is not in these figures";
  const bool all = std::count(poses.lens_block.begin(), poses.lens_block.end(), -1) == 0;
  return "refined lenses (" + refined + ") with their uncertainty (from the self-calibration, or from a check's fit "
         "of a re-zoomed camera), cross terms with the poses included" +
         (all ? std::string() : "; the other cameras' taken as exact");
}

ordered_json CovarianceJson(const registration::PoseUncertainty& poses) {
  ordered_json matrix = ordered_json::array();
  for (Eigen::Index i = 0; i < poses.covariance.rows(); ++i) {
    ordered_json row = ordered_json::array();
    for (Eigen::Index j = 0; j < poses.covariance.cols(); ++j) row.push_back(poses.covariance(i, j));
    matrix.push_back(row);
  }
  ordered_json noise = ordered_json::array();
  for (double value : poses.noise_px) noise.push_back(value);
  ordered_json out = {{"cameras", poses.cameras}, {"noise_px", noise}};
  if (!poses.lens_block.empty()) {
    // The refined lenses' rows follow the poses', in this order per lens block.
    ordered_json blocks = ordered_json::array();
    for (int block : poses.lens_block) blocks.push_back(block >= 0 ? ordered_json(block) : ordered_json(nullptr));
    out["lens_block"] = blocks;
    out["lens_entries"] = {"f", "cx", "cy", "k1", "k2", "p1", "p2", "k3"};
  }
  out["matrix"] = matrix;
  return out;
}

}  // namespace

const char* const kUncertaintyFile = "uncertainty.json";

const std::vector<double>& LevelHeightsM() {
  static const std::vector<double> levels = {0.0, 0.5, kTableHeightM, 1.3, 1.7, kVolumeTopM};
  return levels;
}

VolumeMap MapVolume(const UncertaintyModel& model, const formats::Calibration& calibration) {
  VolumeMap map;
  if (calibration.points.rows() == 0) return map;
  const Eigen::Vector2d low = calibration.points.leftCols<2>().colwise().minCoeff().transpose();
  const Eigen::Vector2d high = calibration.points.leftCols<2>().colwise().maxCoeff().transpose();
  const double longer = std::max(high.x() - low.x(), high.y() - low.y());
  if (!(longer > 0.0)) return map;
  const double step = longer / kCellsAlongLongerSide;
  const int columns = std::max(1, static_cast<int>(std::ceil((high.x() - low.x()) / step)));
  const int rows = std::max(1, static_cast<int>(std::ceil((high.y() - low.y()) / step)));
  map.xs = Centres(low.x(), high.x(), columns);
  map.ys = Centres(low.y(), high.y(), rows);
  const double height_scale = HeightScale(calibration);
  for (double level : LevelHeightsM()) map.zs.push_back(level * height_scale);
  for (double z : map.zs) {
    for (double y : map.ys) {
      for (double x : map.xs) map.cells.push_back(model.Triangulation(Eigen::Vector3d(x, y, z)));
    }
  }
  map.centre = Eigen::Vector3d(0.5 * (low.x() + high.x()), 0.5 * (low.y() + high.y()), kTableHeightM * height_scale);
  map.at_centre = model.Triangulation(map.centre);
  return map;
}

std::string UncertaintyJson(const formats::Calibration& calibration, const UncertaintyModel& model,
                            const VolumeMap& map) {
  std::vector<double> sigmas;
  for (const PointUncertainty& u : map.cells) {
    if (u.determined) sigmas.push_back(u.WorstSigma());
  }
  ordered_json body;
  body["unit"] = calibration.unit;
  // What the bundle adjustment held (ba::Options' gauge): the model says which distance.
  const std::string distance = calibration.model == "free" ? "its distance to the camera farthest from it"
                                                           : "its distance to the floor";
  body["gauge"] = {{"reference_camera", model.reference()},
                   {"held", "the reference camera's pose and " + distance + ": every figure is relative to them"}};
  body["intrinsics"] = IntrinsicsNote(calibration.uncertainty);
  body["centre"] = PointJson(map.centre, map.at_centre, model);
  body["volume"] = {{"cells", map.cells.size()},
                    {"cells_seen_by_2", sigmas.size()},
                    {"median_sigma", Number(Percentile(sigmas, 0.5))},
                    {"p90_sigma", Number(Percentile(sigmas, 0.9))},
                    {"max_sigma", Number(sigmas.empty() ? std::nan("") : *std::max_element(sigmas.begin(), sigmas.end()))}};
  ordered_json cameras = ordered_json::array();
  for (int c = 0; c < model.num_cameras(); ++c) cameras.push_back(CameraJson(model, map, c));
  body["cameras"] = cameras;
  body["map"] = MapJson(map);
  body["pose_covariance"] = CovarianceJson(calibration.uncertainty);
  return formats::DumpSchemaJson("uncertainty", 1, body);
}

bool WriteUncertainty(const std::filesystem::path& directory, const formats::Calibration& calibration,
                      const std::map<std::string, formats::CameraIntrinsics>& intrinsics) {
  if (calibration.uncertainty.empty() || calibration.poses.empty()) return false;
  const UncertaintyModel model(calibration, intrinsics);
  const VolumeMap map = MapVolume(model, calibration);
  formats::AtomicWrite(directory / kUncertaintyFile, UncertaintyJson(calibration, model, map));
  return true;
}

registration::PoseUncertainty ReadPoseUncertainty(const std::filesystem::path& directory) {
  const std::filesystem::path path = directory / kUncertaintyFile;
  const nlohmann::json document = formats::ReadSchemaJson(path, "uncertainty", 1);
  registration::PoseUncertainty out;
  try {
    const nlohmann::json& covariance = document.at("pose_covariance");
    out.cameras = covariance.at("cameras").get<std::vector<std::string>>();
    out.noise_px = covariance.at("noise_px").get<std::vector<double>>();
    out.reference = document.at("gauge").at("reference_camera").get<std::string>();
    if (covariance.contains("lens_block")) {
      for (const nlohmann::json& block : covariance.at("lens_block")) {
        out.lens_block.push_back(block.is_null() ? -1 : block.get<int>());
      }
    }
    const auto rows = covariance.at("matrix").get<std::vector<std::vector<double>>>();
    out.covariance.resize(static_cast<Eigen::Index>(rows.size()), static_cast<Eigen::Index>(rows.size()));
    for (size_t i = 0; i < rows.size(); ++i) {
      if (rows[i].size() != rows.size()) throw std::invalid_argument("pose covariance: the matrix is not square");
      for (size_t j = 0; j < rows.size(); ++j) out.covariance(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) = rows[i][j];
    }
    out.Check();
  } catch (const nlohmann::json::exception& error) {
    throw formats::InputError(path.string() + ": " + error.what());
  } catch (const std::invalid_argument& error) {
    throw formats::InputError(path.string() + ": " + error.what());
  }
  return out;
}

registration::PoseUncertainty StoredPoseUncertainty(const std::filesystem::path& directory,
                                                    const formats::Calibration& calibration, std::string* warning) {
  warning->clear();
  std::error_code error;
  if (!std::filesystem::exists(directory / kUncertaintyFile, error)) return {};
  registration::PoseUncertainty stored;
  try {
    stored = ReadPoseUncertainty(directory);
  } catch (const formats::InputError& problem) {
    *warning = problem.what();
    return {};
  }
  std::vector<std::string> registered, covered = stored.cameras;
  for (const auto& pose : calibration.poses) registered.push_back(pose.name);
  std::sort(registered.begin(), registered.end());
  std::sort(covered.begin(), covered.end());
  if (registered != covered) {
    *warning = (directory / kUncertaintyFile).string() + ": its cameras are not the registered cameras of " +
               directory.string();
    return {};
  }
  return stored;
}

}  // namespace calibproj::uncertainty
