#pragma once
// `calibproj-native check`: a stored results folder tested against the tracks of a
// check projection (`calibproj-native detect` of its videos), with the core's camera
// check, verdicts and repair (check/calibration_check.h), as `calibproj check --tracks`.

#include <CLI/CLI.hpp>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include "calibproj/check/camera_check.h"
#include "calibproj/formats/calibration.h"
#include "calibproj/formats/intrinsics_file.h"
#include "calibproj/formats/tracks_file.h"
#include "interrupts.h"
#include "calibproj/formats/output_folder.h"
#include "calibproj/formats/provenance.h"

namespace calibproj::app {

struct CheckArguments {
  std::string results, tracks, out;
  std::string exports;  // comma-separated export formats of the repaired folder
  bool force = false;
  bool json = false;
  check::CheckOptions options;
  std::vector<std::string> command_line;  // recorded in provenance.json
};

std::shared_ptr<CheckArguments> AddCheckCommand(CLI::App& app, CLI::App** command);

// As `calibproj check` (README, "Exit status"): 0 every camera confirmed or repaired;
// 3 not confirmed (a camera not seen or unknown, a change without --out, fewer than two
// cameras tested); 4 the stored calibration cannot be trusted (nothing written).
int RunCheck(const CheckArguments& arguments, Interrupts& interrupts);

// A stored results folder as a check reads it.
struct StoredResults {
  formats::Calibration calibration;  // with its stored uncertainty
  std::map<std::string, formats::CameraIntrinsics> intrinsics;
  std::map<std::string, std::string> unusable;  // cameras whose intrinsics file is bad
  formats::Tracks tracks;
};
StoredResults ReadStored(const std::string& results);

// The stored calibration checked against `tracks` (named `source` in messages) and,
// with `out` (open), repaired into it (`repaired` says whether it was), its
// provenance.json from `provenance` (the inputs; the command, stored intrinsics, model
// and checked folder are added); prints the table (or JSON); the exit status.
int CheckAgainst(const StoredResults& stored, const formats::Tracks& tracks, const std::string& source,
                 const CheckArguments& arguments, std::optional<formats::OutputFolder>& out,
                 const formats::ProvenanceRecord& provenance, bool* repaired = nullptr);

}  // namespace calibproj::app
