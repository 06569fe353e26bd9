#include "calibrate_command.h"

#include <algorithm>
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>

#include "calibproj/formats/earlier_observations.h"
#include "calibproj/formats/files.h"
#include "calibproj/formats/intrinsics_file.h"
#include "calibproj/formats/output_folder.h"
#include "results_folder.h"
#include "table_flags.h"
#include "calibproj/formats/calibration.h"
#include "calibproj/formats/export.h"
#include "calibproj/formats/scale.h"
#include "calibproj/formats/sequence_file.h"
#include "calibproj/registration/incremental.h"
#include "calibproj/registration/option_table.h"
#include "calibproj/registration/result.h"
#include "calibproj/selfcal/option_table.h"
#include "calibproj/selfcal/rounds.h"
#include "calibproj/formats/tracks_file.h"
#include "calibproj/formats/detect_report.h"
#include "calibproj/video/video_reader.h"

namespace calibproj::app {

using formats::OutputFolder;
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
  cmd->add_option("videos", args->videos, "folder of camera videos (<camera>.mp4)")->type_name("VIDEOS_DIR");
  SharedFlag(cmd, "--tracks", args->tracks);
  SharedFlag(cmd, "--intrinsics", args->intrinsics);
  SharedFlag(cmd, "--out", args->out)->required();
  SharedFlag(cmd, "--force", args->force);
  SharedFlag(cmd, "--scale", args->scale);
  SharedFlag(cmd, "--sequence", args->sequence);
  SharedFlag(cmd, "--merge", args->merge);
  SharedFlag(cmd, "--export", args->exports);
  SharedFlag(cmd, "--json", args->json);
  SharedFlag(cmd, "--nominal-fov", args->nominal_fov);
  // One flag per registration knob, from the table the Python options are made from,
  // so that both commands take the same command lines with the same defaults.
  registration::VisitRegistrationOptions(args->options, TableFlags(cmd, "registration options"));
  AddRefinementFlags(cmd, &args->refine_intrinsics, &args->self_calibration);
  // The ingest of VIDEOS_DIR, as detect takes it; the homography threshold is the
  // registration's here (the ingest keeps its default), as in the Python command.
  AddVideoIngestFlags(cmd, &args->ingest, {"homography_threshold_px"});
  *command = cmd;
  return args;
}

void AddRefinementFlags(CLI::App* command, std::vector<std::string>* refine_intrinsics,
                        selfcal::SelfCalibrationOptions* options) {
  command
      ->add_option("--refine-intrinsics", *refine_intrinsics, selfcal::kRefineIntrinsicsHelp)
      ->type_name("[CAMERA=]ENTRIES")
      ->allow_extra_args(false);
  selfcal::VisitSelfCalibrationOptions(*options,
                                       TableFlags(command, "self-calibration options (with --refine-intrinsics)"));
}

std::optional<LensRefinement> RefinementOption(const std::vector<std::string>& refine_intrinsics,
                                               const selfcal::SelfCalibrationOptions& options) {
  if (refine_intrinsics.empty()) return std::nullopt;
  RequireValidOptions(options);
  try {
    return LensRefinement{selfcal::RefineRequest::Parse(refine_intrinsics), options};
  } catch (const std::invalid_argument& error) {
    throw InputError(error.what());
  }
}

void CheckRefinement(const std::optional<LensRefinement>& refinement, const std::vector<std::string>& cameras) {
  if (!refinement) return;
  try {
    refinement->request.CheckCameras(cameras);
  } catch (const std::invalid_argument& error) {
    throw InputError(error.what());
  }
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

namespace {

// The refined lenses and how they err: the poses' covariance takes them in.
void SetLenses(registration::Reconstruction& reconstruction, const Tracks& tracks,
               const std::map<std::string, CameraIntrinsics>& intrinsics, const selfcal::JointLensCovariance& lenses) {
  std::vector<std::string> names;
  std::vector<int> indices;
  for (const auto& name : lenses.cameras) {
    const auto position = std::find(tracks.cameras.begin(), tracks.cameras.end(), name);
    if (!intrinsics.count(name) || position == tracks.cameras.end()) continue;
    const CameraIntrinsics& in = intrinsics.at(name);
    registration::LensUncertainty lens;
    selfcal::LensOf(in.K, in.dist.data(), static_cast<int>(in.dist.size()), lens.lens, &lens.shape);
    lens.covariance = lenses.Among({name});
    indices.push_back(static_cast<int>(position - tracks.cameras.begin()));
    names.push_back(name);
    reconstruction.SetLensUncertainty(indices.back(), lens);
  }
  reconstruction.SetLensCrossCovariances(indices, lenses.Among(names));
}

registration::RegistrationResult Register(const Tracks& tracks, const std::map<std::string, CameraIntrinsics>& intrinsics,
                                          const registration::Options& options,
                                          const std::optional<formats::ProjectedMarkers>& markers,
                                          const selfcal::JointLensCovariance* lenses = nullptr) {
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
  if (lenses != nullptr) SetLenses(reconstruction, tracks, intrinsics, *lenses);
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
                  const std::function<void(const fs::path& staging)>& extra,
                  const std::optional<LensRefinement>& refinement, bool json) {
  std::map<std::string, CameraIntrinsics> intrinsics = inputs.intrinsics.cameras;
  const formats::ProjectedMarkers* markers = inputs.markers ? &*inputs.markers : nullptr;
  Tracks given = inputs.given;
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
  std::optional<selfcal::SelfCalibration> self_calibration;
  if (refinement && !calibration.poses.empty()) {
    // The registration of the refinement's rounds, of the cameras that can enter it.
    const auto register_tracks = [&](const Tracks& all, const std::map<std::string, CameraIntrinsics>& lenses,
                                     const selfcal::JointLensCovariance* covariance) {
      const Tracks registered = missing.empty() ? all : all.WithoutCameras(missing);
      return formats::FromRegistration(Register(registered, lenses, options, inputs.markers, covariance),
                                       registered.cameras, registered.point_ids, left_out,
                                       registration::ChoiceName(options.model));
    };
    selfcal::RefinedCalibration refined = selfcal::RefineWithRegistrations(
        calibration, given, intrinsics, refinement->request, refinement->options, options.num_threads,
        register_tracks, [](const std::string& line) { std::cerr << line << "\n"; });
    for (const auto& [name, reason] : refined.weak) std::cerr << "camera " << name << " is weak: " << reason << "\n";
    calibration = std::move(refined.calibration);
    given = std::move(refined.tracks);
    tracks = missing.empty() ? given : given.WithoutCameras(missing);
    intrinsics = std::move(refined.intrinsics);
    self_calibration = std::move(refined.result);
  }
  std::string scale_error;
  formats::ProvenanceRecord provenance = inputs.provenance;
  provenance.model = calibration.model;
  provenance.options = options;
  if (measurement && !calibration.poses.empty()) {
    provenance.scale = formats::ScaleSource{measurement->Label(), std::nullopt, ""};
    try {
      const formats::ScaleFit fit = formats::ScaleFactor(calibration, *measurement, markers);
      std::cerr << "scale from " << measurement->Label() << ": " << fit.metres_per_unit << " m per unit\n";
      calibration = formats::Scaled(calibration, fit.metres_per_unit);
      provenance.scale->metres_per_unit = fit.metres_per_unit;
    } catch (const std::invalid_argument& error) {
      scale_error = error.what();
      provenance.scale->error = scale_error;
    }
  }
  const auto write_extra = [&](const fs::path& staging) {
    // First, as the self-calibration: the report shows them.
    formats::WriteProvenance(staging, formats::ProvenanceDocument(provenance, out.path(), [](const std::string& line) {
                               std::cerr << line << "\n";
                             }));
    if (self_calibration) {
      formats::AtomicWrite(staging / selfcal::kSelfCalibrationFile,
                           selfcal::SelfCalibrationJson(*self_calibration, inputs.intrinsics.cameras,
                                                        refinement->options));
    }
    if (extra) extra(staging);
  };
  SaveResults(out, calibration, intrinsics, given, tracks, exports, write_extra);
  if (json) {
    std::cout << formats::SummaryJson(calibration) << "\n";
  } else {
    PrintSummary(calibration, out.path().string());
  }
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

namespace {

// The nominal fields of view a camera may start from (calibrate --nominal-fov), degrees.
constexpr double kMinNominalFovDeg = 10.0;
constexpr double kMaxNominalFovDeg = 170.0;

// Whether a nominal field of view, if given, can be used; intrinsics otherwise.
void CheckNominalFov(const CalibrateArguments& arguments) {
  if (!arguments.nominal_fov) {
    if (arguments.intrinsics.empty()) {
      throw InputError("no intrinsics: give --intrinsics DIR, or --nominal-fov DEG with --refine-intrinsics");
    }
    return;
  }
  if (arguments.refine_intrinsics.empty()) {
    throw InputError("--nominal-fov needs --refine-intrinsics: a guessed focal length must be refined");
  }
  if (arguments.videos.empty()) {
    throw InputError("--nominal-fov needs videos (their frame size); calibrating from tracks needs --intrinsics");
  }
  const double fov = *arguments.nominal_fov;
  if (!(fov >= kMinNominalFovDeg && fov <= kMaxNominalFovDeg)) {
    throw InputError("--nominal-fov must be a horizontal field of view in [10, 170] degrees, got " +
                     formats::PythonFloat(fov));
  }
}

// Videos or tracks, and what applies to each, with the Python command's messages.
void CheckSource(const CalibrateArguments& arguments) {
  if (arguments.videos.empty() == arguments.tracks.empty()) {
    throw InputError("give either VIDEOS_DIR (with --sequence) or --tracks FILE");
  }
  if (!arguments.videos.empty() && arguments.sequence.empty()) {
    throw InputError(arguments.videos + ": calibrating from videos needs --sequence sequence.json");
  }
  if (arguments.videos.empty()) {
    if (!arguments.ingest.exposures.empty()) throw InputError("--exposure applies to videos, not to --tracks");
    if (arguments.ingest.AnyKnobChanged() || !arguments.ingest.detector_options.empty()) {
      throw InputError("ingest and detector options apply to videos, not to --tracks");
    }
  }
  CheckNominalFov(arguments);
}

// The intrinsics of the videos' cameras: from their file where there is one (a bad file
// still fails its camera), else a pinhole of the nominal field of view and the video's
// frame size.
IntrinsicsDir WithNominal(const CalibrateArguments& arguments, std::map<std::string, std::string>* sources) {
  std::map<std::string, std::vector<fs::path>> files;
  if (!arguments.intrinsics.empty()) {
    try {
      files = formats::IntrinsicsFilesIn(arguments.intrinsics);
    } catch (const InputError&) {  // no folder, or no intrinsics file in it: every camera nominal
    }
  }
  IntrinsicsDir out;
  for (const auto& [name, video] : VideoPaths(arguments.videos)) {
    try {
      if (files.count(name)) {
        const fs::path file = formats::IntrinsicsFileOf(arguments.intrinsics, name);
        (*sources)[name] = file.string();
        out.cameras[name] = formats::ReadIntrinsics(file);
        continue;
      }
      const std::string fov = formats::FormatNumber("%g", *arguments.nominal_fov);
      (*sources)[name] = "a nominal " + fov + " deg field of view";
      const video::VideoInfo info = video::ProbeVideo(video.string());
      out.cameras[name] = formats::NominalIntrinsics(name, info.width, info.height, *arguments.nominal_fov);
      std::cerr << "camera " << name << ": no intrinsics file; starting from a " << fov << " deg field of view\n";
    } catch (const std::exception& error) {
      out.unusable[name] = error.what();
    }
  }
  return out;
}

// The ingest's lookup of the intrinsics WithNominal gathered, with where each came from
// (`sources`); a camera whose file is bad fails with its problem.
IntrinsicsLookup IntrinsicsOf(const IntrinsicsDir& intrinsics, const std::map<std::string, std::string>& sources) {
  return [&intrinsics, &sources](const std::string& name, std::string* source) {
    if (const auto bad = intrinsics.unusable.find(name); bad != intrinsics.unusable.end()) {
      throw InputError(bad->second);
    }
    *source = sources.at(name);
    return intrinsics.cameras.at(name);
  };
}

// What provenance.json records of the command line's inputs.
formats::ProvenanceRecord ProvenanceOf(const CalibrateArguments& arguments) {
  formats::ProvenanceRecord record;
  record.command = arguments.command_line;
  record.source = formats::ProvenanceInput{arguments.videos.empty() ? arguments.tracks : arguments.videos, ""};
  if (!arguments.sequence.empty()) record.sequence = formats::ProvenanceInput{arguments.sequence, ""};
  if (!arguments.intrinsics.empty()) record.intrinsics = formats::ProvenanceInput{arguments.intrinsics, ""};
  if (!arguments.merge.empty()) record.merged = formats::ProvenanceInput{arguments.merge, ""};
  return record;
}

}  // namespace

int RunCalibrate(const CalibrateArguments& arguments, Interrupts& interrupts) {
  const std::vector<std::string> exports =
      arguments.exports.empty() ? std::vector<std::string>{} : formats::ParseExportFormats(arguments.exports);
  const auto measurement = ScaleOption(arguments.scale, !arguments.sequence.empty());
  RequireValidOptions(arguments.options);
  const std::optional<LensRefinement> refinement =
      RefinementOption(arguments.refine_intrinsics, arguments.self_calibration);
  CheckSource(arguments);
  // Checked and locked before the inputs are read, as the Python command does.
  OutputFolder out(arguments.out, arguments.force, formats::kCalibrationFiles, &interrupts);
  out.Open();
  CalibrationInputs inputs;
  inputs.provenance = ProvenanceOf(arguments);
  std::map<std::string, std::string> intrinsics_sources;
  if (arguments.nominal_fov) inputs.intrinsics = WithNominal(arguments, &intrinsics_sources);
  std::function<void(const fs::path& staging)> write_report;
  Tracks recorded;
  if (arguments.videos.empty()) {
    recorded = ReadTracks(arguments.tracks);
  } else {
    const ingest::SequenceDescription sequence = formats::ReadSequence(arguments.sequence);
    // With lenses to refine and no ingest knob changed, the core's options for lenses
    // still to be refined (the Python command takes the same).
    VideoIngestArguments ingest = arguments.ingest;
    if (refinement && !ingest.AnyKnobChanged()) ingest.options = ingest::OptionsForUnrefinedLenses();
    const std::vector<formats::CameraOutcome> outcomes =
        arguments.nominal_fov
            ? IngestVideos(arguments.videos, IntrinsicsOf(inputs.intrinsics, intrinsics_sources), sequence, ingest)
            : IngestVideos(arguments.videos, arguments.intrinsics, sequence, ingest);
    recorded = formats::TracksOf(outcomes, sequence.markers_per_array);
    for (const formats::CameraOutcome& camera : outcomes) {
      if (!camera.ok()) inputs.left_out.emplace_back(camera.name, camera.error);
      inputs.provenance.videos.emplace_back(camera.name, camera.video);
    }
    inputs.provenance.markers = sequence.markers.spec;
    inputs.markers = formats::ProjectedMarkers::FromSequence(sequence);
    const nlohmann::ordered_json report = formats::DetectReport(outcomes, arguments.sequence, sequence);
    write_report = [report](const fs::path& staging) {
      formats::AtomicWrite(staging / "detect_report.json", formats::DumpSchemaJson("detect_report", 1, report));
    };
  }
  if (!arguments.nominal_fov) inputs.intrinsics = LoadIntrinsicsDir(arguments.intrinsics);
  inputs.given = arguments.merge.empty()
                     ? recorded
                     : formats::WithEarlierObservations(arguments.merge, recorded, inputs.intrinsics.cameras);
  if (!arguments.sequence.empty() && !inputs.markers) {
    inputs.markers = MarkersOf(arguments.sequence, inputs.given.markers_per_array);
  }
  CheckScale(measurement, inputs.given, inputs.markers);
  CheckRefinement(refinement, inputs.given.cameras);
  inputs.missing_reason = [&](const std::string& camera) {
    return formats::MissingIntrinsicsFile(arguments.intrinsics, camera);
  };
  return CalibrateInto(out, inputs, arguments.options, exports, measurement, write_report, refinement,
                       arguments.json);
}

}  // namespace calibproj::app
