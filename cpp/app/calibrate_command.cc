#include "calibrate_command.h"

#include <filesystem>
#include <iostream>
#include <map>
#include <optional>

#include "calibproj/formats/earlier_observations.h"
#include "calibproj/formats/files.h"
#include "calibproj/formats/intrinsics_file.h"
#include "output_folder.h"
#include "calibproj/formats/calibration.h"
#include "calibproj/formats/export.h"
#include "calibproj/formats/scale.h"
#include "calibproj/formats/sequence_file.h"
#include "calibproj/registration/incremental.h"
#include "calibproj/registration/result.h"
#include "calibproj/formats/tracks_file.h"

namespace calibproj::app {

using formats::CameraIntrinsics;
using formats::InputError;
using formats::IntrinsicsDir;
using formats::LoadIntrinsicsDir;
using formats::ReadTracks;
using formats::Tracks;

namespace fs = std::filesystem;

std::shared_ptr<CalibrateArguments> AddCalibrateCommand(CLI::App& app, CLI::App** command) {
  auto args = std::make_shared<CalibrateArguments>();
  CLI::App* cmd = app.add_subcommand(
      "calibrate",
      "Calibrate the cameras: register every camera and refine, then write camera_poses.json, metrics.json and "
      "points.ply (floor frame: z up, floor z = 0), the tracks.json and intrinsics/ they came from, and the exports "
      "asked for. An existing results folder is only overwritten with --force.");
  cmd->add_option("--tracks", args->tracks, "tracks.json to calibrate from")->required();
  cmd->add_option("--intrinsics", args->intrinsics, "folder of per-camera intrinsics files")->required();
  cmd->add_option("--out", args->out, "results folder")->required();
  cmd->add_flag("--force", args->force, "overwrite the results of an earlier run in --out");
  cmd->add_option("--scale", args->scale,
                  "metric scale from one measurement: camera-height:NAME=METRES, distance:CAM_A,CAM_B=METRES or "
                  "marker-size:[ARRAY/MARKER=]METRES (default: arbitrary unit)");
  cmd->add_option("--sequence", args->sequence, "sequence.json of the projection: its projector pixels tie every centre to the floor (and --scale marker-size needs it)");
  cmd->add_option("--merge", args->merge,
                  "add the observations of an earlier calibration (its results folder or tracks.json): --tracks "
                  "then come from a projection planned by `calibproj generate --densify`, and --sequence is that "
                  "densified sequence.json; same intrinsics as the earlier results");
  cmd->add_option("--export", args->exports,
                  "also write the calibration as yaml, colmap and/or anipose (comma-separated)");
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
  option("--error-correlation", o.error_correlation,
         "correlation of one camera's centre errors: the uncertainty counts N centres as N / (1 + (N - 1) * this)");
  option("--floor-relief", o.floor_relief,
         "expected rms height of the floor's unevenness, a share of the extent of its centres (0: flat)");
  *command = cmd;
  return args;
}

namespace {

// The results, the inputs they came from (tracks.json and intrinsics/, as the Python
// command keeps them) and the exports, written into the staging folder, then moved
// into place.
void SaveResults(OutputFolder& folder, const formats::Calibration& calibration,
                 const std::map<std::string, CameraIntrinsics>& intrinsics, const Tracks& given,
                 const Tracks& tracks, const std::vector<std::string>& exports) {
  folder.Write([&](const fs::path& staging) {
    for (const auto& name : given.cameras) {
      if (intrinsics.count(name)) formats::WriteIntrinsics(staging / "intrinsics" / (name + ".json"), intrinsics.at(name));
    }
    formats::WriteTracks(staging / "tracks.json", given);
    formats::WriteCalibration(staging, calibration);
    std::vector<std::string> warnings;
    if (calibration.poses.empty() && !exports.empty()) {
      warnings.push_back("no camera registered: nothing exported");  // the failures in metrics.json say why
    } else {
      for (const auto& format : exports) formats::Export(calibration, format, staging, intrinsics, &tracks, &warnings);
    }
    for (const auto& warning : warnings) std::cerr << warning << "\n";
  });
  folder.Commit();
}

// The MSM geometry of sequence.json, checked against the tracks it should belong to.
formats::ProjectedMarkers MarkersOf(const std::string& sequence, std::optional<int> markers_per_array) {
  formats::ProjectedMarkers markers = formats::ProjectedMarkers::FromSequence(formats::ReadSequence(sequence));
  if (markers_per_array && *markers_per_array != markers.markers_per_array) {
    throw InputError(sequence + ": " + std::to_string(markers.markers_per_array) +
                     " markers per array, but the tracks have " + std::to_string(*markers_per_array) +
                     "; is it the sequence of these tracks?");
  }
  return markers;
}

void CheckScale(const formats::ScaleMeasurement& measurement, const std::vector<std::string>& cameras,
                const formats::ProjectedMarkers* markers) {
  try {
    formats::CheckMeasurement(measurement, cameras, markers);
  } catch (const std::invalid_argument& error) {
    throw InputError(error.what());
  }
}

registration::RegistrationResult Register(const Tracks& tracks, const std::map<std::string, CameraIntrinsics>& intrinsics,
                                          const CalibrateArguments& arguments,
                                          const std::optional<formats::ProjectedMarkers>& markers) {
  std::vector<registration::Camera> cameras;
  for (const auto& name : tracks.cameras) {
    const CameraIntrinsics& in = intrinsics.at(name);
    registration::Camera camera;
    camera.K = {in.K(0, 0), in.K(1, 1), in.K(0, 2), in.K(1, 2), in.K(0, 1)};
    camera.width = in.ImageWidth();
    camera.height = in.ImageHeight();
    cameras.push_back(camera);
  }
  if (cameras.empty()) return {};  // every camera failed before registration
  registration::Options options = arguments.options;
  options.model = arguments.model == "free" ? ba::Model::kFree : ba::Model::kCoplanar;
  options.loss = arguments.loss == "huber" ? ba::Loss::kHuber : arguments.loss == "cauchy" ? ba::Loss::kCauchy
                                                                                           : ba::Loss::kNone;
  registration::Reconstruction reconstruction(cameras, static_cast<int>(tracks.point_ids.size()), tracks.camera_index,
                                              tracks.point_index, tracks.xy, options);
  if (markers) reconstruction.SetProjector(markers->PixelsOf(tracks.point_ids), markers->projector_width, markers->projector_height);
  registration::Run(
      reconstruction, [](const std::string& message) { std::cerr << message << "\n"; }, tracks.cameras);
  return registration::Summarize(reconstruction);
}

void PrintSummary(const formats::Calibration& calibration, const std::string& out) {
  for (const auto& [name, metrics] : calibration.metrics) {
    if (calibration.PoseOf(name)) {
      std::cout << name << ": registered, mean " << *metrics.mean_px << " px, " << metrics.inliers << " inliers\n";
    } else {
      std::cout << name << ": FAILED " << metrics.failure.value_or("") << "\n";
    }
  }
  std::cout << "results in " << out << " (unit: " << calibration.unit << ")\n";
}

}  // namespace

int RunCalibrate(const CalibrateArguments& arguments, Interrupts& interrupts) {
  const std::vector<std::string> exports =
      arguments.exports.empty() ? std::vector<std::string>{} : formats::ParseExportFormats(arguments.exports);
  std::optional<formats::ScaleMeasurement> measurement;
  if (!arguments.scale.empty()) measurement = formats::ParseScale(arguments.scale);
  if (measurement && measurement->kind == "marker-size" && arguments.sequence.empty()) {
    throw InputError("--scale " + arguments.scale + ": marker-size needs --sequence (the projection's sequence.json)");
  }
  // Checked and locked before the inputs are read, as the Python command does.
  OutputFolder out(arguments.out, arguments.force, formats::kCalibrationFiles, interrupts);
  out.Open();
  const Tracks recorded = ReadTracks(arguments.tracks);
  const IntrinsicsDir folder = LoadIntrinsicsDir(arguments.intrinsics);
  const auto& intrinsics = folder.cameras;
  const Tracks given =
      arguments.merge.empty() ? recorded : formats::WithEarlierObservations(arguments.merge, recorded, intrinsics);
  Tracks tracks = given;
  std::optional<formats::ProjectedMarkers> markers;
  if (!arguments.sequence.empty()) markers = MarkersOf(arguments.sequence, tracks.markers_per_array);
  if (measurement) {
    CheckScale(*measurement, tracks.cameras, markers ? &*markers : nullptr);
  }

  std::vector<formats::NamedText> left_out;
  std::vector<std::string> missing;
  for (const auto& camera : tracks.cameras) {
    if (intrinsics.count(camera)) continue;
    // A camera whose file is bad fails alone, with the file and its problem.
    const auto bad = folder.unusable.find(camera);
    const std::string reason =
        bad != folder.unusable.end() ? bad->second : formats::MissingIntrinsicsFile(arguments.intrinsics, camera);
    missing.push_back(camera);
    left_out.emplace_back(camera, reason);
    std::cerr << "camera " << camera << ": " << reason << ", left out\n";
  }
  if (!missing.empty()) tracks = tracks.WithoutCameras(missing);

  formats::Calibration calibration =
      formats::FromRegistration(Register(tracks, intrinsics, arguments, markers), tracks.cameras, tracks.point_ids, left_out,
                                arguments.model);
  std::string scale_error;
  if (measurement && !calibration.poses.empty()) {
    try {
      const formats::ScaleFit fit =
          formats::ScaleFactor(calibration, *measurement, markers ? &*markers : nullptr);
      std::cerr << "scale from " << measurement->Label() << ": " << fit.metres_per_unit << " m per unit\n";
      calibration = formats::Scaled(calibration, fit.metres_per_unit);
    } catch (const std::invalid_argument& error) {
      scale_error = error.what();
    }
  }
  SaveResults(out, calibration, intrinsics, given, tracks, exports);
  PrintSummary(calibration, arguments.out);
  if (!scale_error.empty()) {
    throw InputError(scale_error + "; results written to " + arguments.out + " in arbitrary units");
  }
  return calibration.failed.empty() ? 0 : 1;
}

}  // namespace calibproj::app
