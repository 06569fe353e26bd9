#pragma once
// `calibproj-native check`: a stored results folder tested against the tracks of a
// check projection (`calibproj-native detect` of its videos), with the core's camera
// check, verdicts and repair (check/calibration_check.h), as `calibproj check --tracks`.

#include <CLI/CLI.hpp>
#include <memory>
#include <string>

#include "calibproj/check/camera_check.h"
#include "interrupts.h"

namespace calibproj::app {

struct CheckArguments {
  std::string results, tracks, out;
  std::string exports;  // comma-separated export formats of the repaired folder
  bool force = false;
  bool json = false;
  check::CheckOptions options;
};

std::shared_ptr<CheckArguments> AddCheckCommand(CLI::App& app, CLI::App** command);

// As `calibproj check` (README, "Exit status"): 0 every camera confirmed or repaired;
// 3 not confirmed (a camera not seen or unknown, a change without --out, fewer than two
// cameras tested); 4 the stored calibration cannot be trusted (nothing written).
int RunCheck(const CheckArguments& arguments, Interrupts& interrupts);

}  // namespace calibproj::app
