#pragma once
// `calibproj-native capture`: the room run from its site file, as `calibproj capture`
// does it: every camera recorded and ingested live while the projector plays the
// projection (calibproj/capture/session.h), then calibrated, or with --check the stored
// calibration checked and repaired.

#include <CLI/CLI.hpp>
#include <memory>
#include <string>
#include <vector>

#include "calibproj/registration/reconstruction.h"
#include "calibproj/selfcal/refinement.h"
#include "interrupts.h"

namespace calibproj::app {

struct CaptureArguments {
  std::string site, out, recordings;
  std::string check;                 // a stored results folder to check instead of calibrating
  std::string sequence, projection;  // another projection than the site file's
  std::string scale, exports;
  bool force = false;
  bool no_progress = false;
  registration::Options options;
  std::vector<std::string> refine_intrinsics;  // as calibrate's
  selfcal::SelfCalibrationOptions self_calibration;
  std::vector<std::string> command_line;  // recorded in provenance.json
  bool json = false;                      // the summary as JSON (formats::SummaryJson)
};

std::shared_ptr<CaptureArguments> AddCaptureCommand(CLI::App& app, CLI::App** command);

// As `calibproj capture` (README, "Exit status"): 0 every camera calibrated, 1 a camera
// failed or the projector could not play, 2 a bad site file or option; with --check,
// `check`'s statuses (0, 3, 4). The recordings are kept whatever happens.
int RunCapture(const CaptureArguments& arguments, Interrupts& interrupts);

}  // namespace calibproj::app
