#pragma once
// `calibproj-native calibrate`: camera videos (with sequence.json) or tracks, and
// intrinsics -> camera_poses.json, metrics.json, points.ply and the exports, with the
// same ingest (video_ingest.h), registration steps (calibproj::registration::Run),
// options, metric scale and file writers as `calibproj calibrate`.

#include <CLI/CLI.hpp>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "calibproj/formats/calibration.h"
#include "calibproj/formats/intrinsics_file.h"
#include "calibproj/formats/provenance.h"
#include "calibproj/formats/scale.h"
#include "calibproj/formats/tracks_file.h"
#include "calibproj/registration/reconstruction.h"
#include "calibproj/selfcal/refinement.h"
#include "interrupts.h"
#include "video_ingest.h"
#include "calibproj/formats/output_folder.h"

namespace calibproj::app {

struct CalibrateArguments {
  std::string videos;  // a folder of camera videos to ingest, or empty with --tracks
  std::string tracks, intrinsics, out;
  std::string scale;     // one metric measurement (formats/scale.h); empty: arbitrary unit
  std::string sequence;  // sequence.json, for a marker-size measurement
  std::string exports;   // comma-separated export formats (formats/export.h)
  std::string merge;     // earlier results folder or tracks.json whose observations are added
  bool force = false;
  registration::Options options;
  std::vector<std::string> refine_intrinsics;  // [CAMERA=]ENTRIES items; empty: the intrinsics as given
  selfcal::SelfCalibrationOptions self_calibration;
  VideoIngestArguments ingest;  // with VIDEOS_DIR
  std::vector<std::string> command_line;  // recorded in provenance.json
  bool json = false;                      // the summary as JSON (formats::SummaryJson)
  // With videos and --refine-intrinsics: the horizontal field of view (deg) a camera
  // without an intrinsics file starts from.
  std::optional<double> nominal_fov;
};

// What to refine of the intrinsics, and how (calibrate --refine-intrinsics).
struct LensRefinement {
  selfcal::RefineRequest request;
  selfcal::SelfCalibrationOptions options;
};

// --refine-intrinsics and the self-calibration's knobs (its option table) on `command`.
void AddRefinementFlags(CLI::App* command, std::vector<std::string>* refine_intrinsics,
                        selfcal::SelfCalibrationOptions* options);
// The refinement the flags ask for (none without --refine-intrinsics); InputError for a
// bad request or knob.
std::optional<LensRefinement> RefinementOption(const std::vector<std::string>& refine_intrinsics,
                                               const selfcal::SelfCalibrationOptions& options);
// InputError when the refinement names a camera that is not among `cameras`.
void CheckRefinement(const std::optional<LensRefinement>& refinement, const std::vector<std::string>& cameras);

// Adds the subcommand and its options to the app; the returned arguments are filled
// when the command line is parsed.
std::shared_ptr<CalibrateArguments> AddCalibrateCommand(CLI::App& app, CLI::App** command);

// 0 when every camera was calibrated, 1 when some were not (the others are written),
// as `calibproj calibrate` (README, "Exit status").
// The results folder is written as one transaction (output_folder.h).
int RunCalibrate(const CalibrateArguments& arguments, Interrupts& interrupts);

// What a calibration is made from (calibrate: files; capture: what the cameras sent).
struct CalibrationInputs {
  formats::Tracks given;                         // as tracks.json keeps them
  formats::IntrinsicsDir intrinsics;
  std::vector<formats::NamedText> left_out;      // cameras that failed before, and why
  std::optional<formats::ProjectedMarkers> markers;
  // Why a camera of the tracks has no intrinsics, when the folder does not say.
  std::function<std::string(const std::string& camera)> missing_reason;
  // What provenance.json records of the inputs; CalibrateInto adds the model, options
  // and scale.
  formats::ProvenanceRecord provenance;
};

// Registers, refines (the lenses too with `refinement`: self_calibration.json, and
// intrinsics/ and tracks.json follow the refined lenses), scales and writes the results
// into `out` (open) with what `extra` writes into its staging folder; prints the
// summary (as JSON with `json`). 0 every camera calibrated, 1 not. InputError when the scale cannot be applied
// (the results are then written unscaled).
int CalibrateInto(formats::OutputFolder& out, const CalibrationInputs& inputs, const registration::Options& options,
                  const std::vector<std::string>& exports, const std::optional<formats::ScaleMeasurement>& measurement,
                  const std::function<void(const std::filesystem::path& staging)>& extra = {},
                  const std::optional<LensRefinement>& refinement = std::nullopt, bool json = false);

// --scale MEASUREMENT parsed (none when empty); marker-size needs the projection's sequence.
std::optional<formats::ScaleMeasurement> ScaleOption(const std::string& scale, bool has_sequence);
// InputError when the measurement names cameras or markers the tracks do not have.
void CheckScale(const std::optional<formats::ScaleMeasurement>& measurement, const formats::Tracks& tracks,
                const std::optional<formats::ProjectedMarkers>& markers);
// The MSM geometry of sequence.json, checked against the tracks' markers per array.
formats::ProjectedMarkers MarkersOf(const std::string& sequence, std::optional<int> markers_per_array);

}  // namespace calibproj::app
