#include "calibrate_command.h"

#include <algorithm>
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>

#include "calibproj/formats/earlier_observations.h"
#include "calibproj/formats/files.h"
#include "calibproj/formats/intrinsics_file.h"
#include "output_folder.h"
#include "results_folder.h"
#include "table_flags.h"
#include "calibproj/formats/calibration.h"
#include "calibproj/formats/export.h"
#include "calibproj/formats/scale.h"
#include "calibproj/formats/sequence_file.h"
#include "calibproj/registration/incremental.h"
#include "calibproj/registration/option_table.h"
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
  // One flag per registration knob, from the table the Python options are made from,
  // so that both commands take the same command lines with the same defaults.
  registration::VisitRegistrationOptions(args->options, TableFlags(cmd, "registration options"));
  *command = cmd;
  return args;
}

namespace {

}  // namespace

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

namespace {

registration::RegistrationResult Register(const Tracks& tracks, const std::map<std::string, CameraIntrinsics>& intrinsics,
                                          const registration::Options& options,
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
  registration::Reconstruction reconstruction(cameras, static_cast<int>(tracks.point_ids.size()), tracks.camera_index,
                                              tracks.point_index, tracks.xy, options);
  if (markers) {
    reconstruction.SetProjector(markers->PixelsOf(tracks.point_ids), markers->projector_width,
                                markers->projector_height, markers->LargestSidesOf(tracks.point_ids));
  }
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

int CalibrateInto(OutputFolder& out, const CalibrationInputs& inputs, const registration::Options& options,
                  const std::vector<std::string>& exports, const std::optional<formats::ScaleMeasurement>& measurement,
                  const std::function<void(const fs::path& staging)>& extra) {
  const auto& intrinsics = inputs.intrinsics.cameras;
  const formats::ProjectedMarkers* markers = inputs.markers ? &*inputs.markers : nullptr;
  Tracks tracks = inputs.given;
  std::vector<formats::NamedText> left_out = inputs.left_out;
  std::vector<std::string> missing;
  for (const auto& [camera, reason] : left_out) missing.push_back(camera);
  for (const auto& camera : tracks.cameras) {
    if (intrinsics.count(camera) || std::find(missing.begin(), missing.end(), camera) != missing.end()) continue;
    // A camera whose file is bad fails alone, with the file and its problem.
    const auto bad = inputs.intrinsics.unusable.find(camera);
    const std::string reason = bad != inputs.intrinsics.unusable.end() ? bad->second : inputs.missing_reason(camera);
    missing.push_back(camera);
    left_out.emplace_back(camera, reason);
    std::cerr << "camera " << camera << ": " << reason << ", left out\n";
  }
  if (!missing.empty()) tracks = tracks.WithoutCameras(missing);

  formats::Calibration calibration =
      formats::FromRegistration(Register(tracks, intrinsics, options, inputs.markers), tracks.cameras,
                                tracks.point_ids, left_out, registration::ChoiceName(options.model));
  std::string scale_error;
  if (measurement && !calibration.poses.empty()) {
    try {
      const formats::ScaleFit fit = formats::ScaleFactor(calibration, *measurement, markers);
      std::cerr << "scale from " << measurement->Label() << ": " << fit.metres_per_unit << " m per unit\n";
      calibration = formats::Scaled(calibration, fit.metres_per_unit);
    } catch (const std::invalid_argument& error) {
      scale_error = error.what();
    }
  }
  SaveResults(out, calibration, intrinsics, inputs.given, tracks, exports, extra);
  PrintSummary(calibration, out.path().string());
  if (!scale_error.empty()) {
    throw InputError(scale_error + "; results written to " + out.path().string() + " in arbitrary units");
  }
  return calibration.failed.empty() ? 0 : 1;
}

std::optional<formats::ScaleMeasurement> ScaleOption(const std::string& scale, bool has_sequence) {
  if (scale.empty()) return std::nullopt;
  formats::ScaleMeasurement measurement = formats::ParseScale(scale);
  if (measurement.kind == "marker-size" && !has_sequence) {
    throw InputError("--scale " + scale + ": marker-size needs --sequence (the projection's sequence.json)");
  }
  return measurement;
}

void CheckScale(const std::optional<formats::ScaleMeasurement>& measurement, const Tracks& tracks,
                const std::optional<formats::ProjectedMarkers>& markers) {
  if (!measurement) return;
  try {
    formats::CheckMeasurement(*measurement, tracks.cameras, markers ? &*markers : nullptr);
  } catch (const std::invalid_argument& error) {
    throw InputError(error.what());
  }
}

int RunCalibrate(const CalibrateArguments& arguments, Interrupts& interrupts) {
  const std::vector<std::string> exports =
      arguments.exports.empty() ? std::vector<std::string>{} : formats::ParseExportFormats(arguments.exports);
  const auto measurement = ScaleOption(arguments.scale, !arguments.sequence.empty());
  RequireValidOptions(arguments.options);
  // Checked and locked before the inputs are read, as the Python command does.
  OutputFolder out(arguments.out, arguments.force, formats::kCalibrationFiles, interrupts);
  out.Open();
  const Tracks recorded = ReadTracks(arguments.tracks);
  CalibrationInputs inputs;
  inputs.intrinsics = LoadIntrinsicsDir(arguments.intrinsics);
  inputs.given = arguments.merge.empty()
                     ? recorded
                     : formats::WithEarlierObservations(arguments.merge, recorded, inputs.intrinsics.cameras);
  if (!arguments.sequence.empty()) inputs.markers = MarkersOf(arguments.sequence, inputs.given.markers_per_array);
  CheckScale(measurement, inputs.given, inputs.markers);
  inputs.missing_reason = [&](const std::string& camera) {
    return formats::MissingIntrinsicsFile(arguments.intrinsics, camera);
  };
  return CalibrateInto(out, inputs, arguments.options, exports, measurement);
}

}  // namespace calibproj::app
