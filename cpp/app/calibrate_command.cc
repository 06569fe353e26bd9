#include "calibrate_command.h"

#include <filesystem>
#include <iostream>

#include "calibproj/formats/files.h"
#include "calibproj/formats/intrinsics_file.h"
#include "output_folder.h"
#include "calibproj/formats/results_file.h"
#include "calibproj/registration/incremental.h"
#include "calibproj/registration/result.h"
#include "calibproj/formats/tracks_file.h"

namespace calibproj::app {

using formats::CameraIntrinsics;
using formats::IntrinsicsDir;
using formats::LoadIntrinsicsDir;
using formats::ReadTracks;
using formats::ResultFiles;
using formats::Tracks;
using formats::WriteResults;
using formats::kResultFiles;

namespace fs = std::filesystem;

std::shared_ptr<CalibrateArguments> AddCalibrateCommand(CLI::App& app, CLI::App** command) {
  auto args = std::make_shared<CalibrateArguments>();
  CLI::App* cmd = app.add_subcommand(
      "calibrate",
      "Calibrate the cameras: register every camera and refine, then write camera_poses.json, metrics.json and "
      "points.ply (floor frame: z up, floor z = 0). An existing results folder is only overwritten with --force.");
  cmd->add_option("--tracks", args->tracks, "tracks.json to calibrate from")->required();
  cmd->add_option("--intrinsics", args->intrinsics, "folder of per-camera intrinsics files")->required();
  cmd->add_option("--out", args->out, "results folder")->required();
  cmd->add_flag("--force", args->force, "overwrite the results of an earlier run in --out");
  registration::Options& o = args->options;
  const auto option = [cmd](const std::string& name, auto& value, const std::string& help) {
    cmd->add_option(name, value, help)->capture_default_str();
  };
  cmd->add_option("--model", args->model, "coplanar (points on one refined plane) or free (3D points)")
      ->check(CLI::IsMember({"free", "coplanar"}))
      ->capture_default_str();
  option("--homography-threshold-px", o.homography_threshold_px, "initial pair RANSAC threshold, each camera's px");
  option("--pnp-threshold-px", o.pnp_threshold_px, "PnP RANSAC threshold, in the new camera's px");
  option("--ransac-max-iterations", o.ransac_max_iterations, "upper bound of RANSAC iterations");
  option("--ransac-confidence", o.ransac_confidence, "RANSAC stops once a better model is this unlikely");
  option("--seed", o.seed, "RANSAC random seed");
  option("--min-pair-points", o.min_pair_points, "common points for the initial pair and the third camera");
  option("--min-pnp-points", o.min_pnp_points, "correspondences needed to register a camera");
  option("--min-triangulation-angle-deg", o.min_triangulation_angle_deg, "FREE: parallax to triangulate a point");
  option("--min-pair-parallax-deg", o.min_pair_parallax_deg, "median parallax of the initial pair's points");
  option("--outlier-threshold-px", o.outlier_threshold_px, "smallest reprojection error at which an observation goes");
  option("--outlier-sigma-factor", o.outlier_sigma_factor, "threshold = max(outlier-threshold-px, factor * sigma)");
  option("--max-refine-rounds", o.max_refine_rounds, "bundle adjustment and outlier rounds at the end");
  option("--view-score-levels", o.view_score_levels, "levels of the view score's visibility pyramid");
  cmd->add_option("--loss", args->loss, "robust loss: none, huber, cauchy")
      ->check(CLI::IsMember({"none", "huber", "cauchy"}))
      ->capture_default_str();
  option("--loss-scale-px", o.loss_scale_px, "scale of the robust loss in pixels");
  option("--num-threads", o.num_threads, "threads of the bundle adjustment");
  option("--intermediate-ba-iterations", o.intermediate_ba_iterations, "BA iterations after each camera");
  option("--final-ba-iterations", o.final_ba_iterations, "iterations of the final bundle adjustments");
  option("--weak-rotation-sigma-deg", o.weak_rotation_sigma_deg,
         "cameras whose rotation is known worse than this (1 sigma) are reported as weak");
  *command = cmd;
  return args;
}

namespace {

// The results written into the staging folder, then moved into place.
void SaveResults(OutputFolder& folder, const registration::RegistrationResult& result, const ResultFiles& names) {
  folder.Write([&](const fs::path& staging) { WriteResults(staging, result, names); });
  folder.Commit();
}

}  // namespace

int RunCalibrate(const CalibrateArguments& arguments, Interrupts& interrupts) {
  // Checked and locked before the inputs are read, as the Python command does.
  OutputFolder out(arguments.out, arguments.force, kResultFiles, interrupts);
  out.Open();
  Tracks tracks = ReadTracks(arguments.tracks);
  const IntrinsicsDir folder = LoadIntrinsicsDir(arguments.intrinsics);
  const auto& intrinsics = folder.cameras;

  ResultFiles names;
  names.model = arguments.model;
  std::vector<std::string> missing;
  for (const auto& camera : tracks.cameras) {
    if (intrinsics.count(camera)) continue;
    // A camera whose file is bad fails alone, with the file and its problem.
    const auto bad = folder.unusable.find(camera);
    const std::string reason = bad != folder.unusable.end() ? bad->second : "no intrinsics for this camera";
    missing.push_back(camera);
    names.left_out.emplace_back(camera, reason);
    std::cerr << "camera " << camera << ": " << reason << ", left out\n";
  }
  if (!missing.empty()) tracks = tracks.WithoutCameras(missing);

  std::vector<registration::Camera> cameras;
  for (const auto& name : tracks.cameras) {
    const CameraIntrinsics& in = intrinsics.at(name);
    registration::Camera camera;
    camera.K = {in.K(0, 0), in.K(1, 1), in.K(0, 2), in.K(1, 2), in.K(0, 1)};
    camera.width = in.ImageWidth();
    camera.height = in.ImageHeight();
    cameras.push_back(camera);
  }
  names.cameras = tracks.cameras;
  names.point_ids = tracks.point_ids;
  if (cameras.empty()) {  // every camera failed before registration
    SaveResults(out, registration::RegistrationResult{}, names);
    for (const auto& [name, reason] : names.left_out) std::cout << name << ": FAILED " << reason << "\n";
    return 1;
  }
  registration::Options options = arguments.options;
  options.model = arguments.model == "free" ? ba::Model::kFree : ba::Model::kCoplanar;
  options.loss = arguments.loss == "huber" ? ba::Loss::kHuber : arguments.loss == "cauchy" ? ba::Loss::kCauchy
                                                                                           : ba::Loss::kNone;
  registration::Reconstruction reconstruction(cameras, static_cast<int>(tracks.point_ids.size()), tracks.camera_index,
                                              tracks.point_index, tracks.xy, options);
  registration::Run(
      reconstruction, [](const std::string& message) { std::cerr << message << "\n"; }, tracks.cameras);
  const registration::RegistrationResult result = registration::Summarize(reconstruction);

  SaveResults(out, result, names);
  int registered = 0;
  for (size_t c = 0; c < result.cameras.size(); ++c) {
    const auto& camera = result.cameras[c];
    registered += camera.registered;
    if (camera.registered) {
      std::cout << tracks.cameras[c] << ": registered, mean " << camera.mean_px << " px, " << camera.inliers
                << " inliers\n";
    } else {
      std::cout << tracks.cameras[c] << ": FAILED " << camera.failure << "\n";
    }
  }
  for (const auto& [name, reason] : names.left_out) std::cout << name << ": FAILED " << reason << "\n";
  std::cout << "results in " << arguments.out << " (unit: arbitrary)\n";
  const bool all_calibrated = registered == static_cast<int>(result.cameras.size()) && names.left_out.empty();
  return all_calibrated ? 0 : 1;
}

}  // namespace calibproj::app
