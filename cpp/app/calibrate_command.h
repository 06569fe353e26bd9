#pragma once
// `calibproj-native calibrate`: tracks + intrinsics -> camera_poses.json, metrics.json,
// points.ply and the exports, with the same registration steps
// (calibproj::registration::Run), options, metric scale and file writers as
// `calibproj calibrate --tracks`.

#include <CLI/CLI.hpp>
#include <memory>
#include <string>

#include "calibproj/registration/reconstruction.h"
#include "interrupts.h"

namespace calibproj::app {

struct CalibrateArguments {
  std::string tracks, intrinsics, out;
  std::string scale;     // one metric measurement (formats/scale.h); empty: arbitrary unit
  std::string sequence;  // sequence.json, for a marker-size measurement
  std::string exports;   // comma-separated export formats (formats/export.h)
  std::string merge;     // earlier results folder or tracks.json whose observations are added
  bool force = false;
  registration::Options options;
};

// Adds the subcommand and its options to the app; the returned arguments are filled
// when the command line is parsed.
std::shared_ptr<CalibrateArguments> AddCalibrateCommand(CLI::App& app, CLI::App** command);

// 0 when every camera was calibrated, 1 when some were not (the others are written),
// as `calibproj calibrate` (README, "Exit status").
// The results folder is written as one transaction (output_folder.h).
int RunCalibrate(const CalibrateArguments& arguments, Interrupts& interrupts);

}  // namespace calibproj::app
