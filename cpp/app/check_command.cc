#include "check_command.h"

#include <filesystem>
#include <iostream>
#include <map>

#include "calibproj/check/calibration_check.h"
#include "calibproj/check/option_table.h"
#include "calibproj/formats/calibration.h"
#include "calibproj/formats/export.h"
#include "calibproj/formats/files.h"
#include "calibproj/formats/intrinsics_file.h"
#include "calibproj/formats/tracks_file.h"
#include "calibproj/registration/reconstruction.h"
#include "calibproj/uncertainty/volume_map.h"
#include "calibproj/formats/output_folder.h"
#include "results_folder.h"
#include "table_flags.h"

namespace calibproj::app {

using formats::OutputFolder;
namespace fs = std::filesystem;
using formats::InputError;

std::shared_ptr<CheckArguments> AddCheckCommand(CLI::App& app, CLI::App** command) {
  auto args = std::make_shared<CheckArguments>();
  CLI::App* cmd = app.add_subcommand(
      "check",
      "Check a calibration with a short projection (`calibproj generate --check RESULTS`): every camera of RESULTS "
      "tested against the check projection's tracks (`calibproj-native detect` of its videos, undistorted with "
      "RESULTS/intrinsics): unchanged, moved, rezoomed, not seen or unknown. With --out, the moved and re-zoomed "
      "cameras are re-fitted against the unchanged ones and a complete results folder is written there, with "
      "check.json.");
  cmd->add_option("results", args->results, "results folder of `calibrate`")->required();
  SharedFlag(cmd, "--tracks", args->tracks)->required();
  SharedFlag(cmd, "--out", args->out);
  SharedFlag(cmd, "--force", args->force);
  SharedFlag(cmd, "--export", args->exports);
  SharedFlag(cmd, "--json", args->json);
  check::VisitCheckOptions(args->options, TableFlags(cmd, "check options"));
  *command = cmd;
  return args;
}

namespace {

// The intrinsics of the named cameras in `folder`, and why the others have none (a bad,
// missing or doubled file fails its own camera only).
std::map<std::string, formats::CameraIntrinsics> IntrinsicsOf(const fs::path& folder,
                                                              const std::vector<formats::CameraPose>& cameras,
                                                              std::map<std::string, std::string>* unusable) {
  formats::IntrinsicsFilesIn(folder);  // the folder exists and holds intrinsics files
  std::map<std::string, formats::CameraIntrinsics> intrinsics;
  for (const auto& camera : cameras) {
    try {
      intrinsics[camera.name] = formats::ReadIntrinsics(formats::IntrinsicsFileOf(folder, camera.name), camera.name);
    } catch (const InputError& error) {
      (*unusable)[camera.name] = error.what();
    }
  }
  return intrinsics;
}

}  // namespace

StoredResults ReadStored(const std::string& folder) {
  const fs::path results = folder;
  StoredResults stored;
  stored.calibration = formats::ReadCalibration(results);
  // The stored covariance, which the repair carries over (a bad file only costs it).
  std::string warning;
  stored.calibration.uncertainty = uncertainty::StoredPoseUncertainty(results, stored.calibration, &warning);
  if (!warning.empty()) std::cerr << warning << "; the repaired results will have no uncertainty.json\n";
  stored.intrinsics = IntrinsicsOf(results / "intrinsics", stored.calibration.poses, &stored.unusable);
  stored.tracks = formats::ReadTracks(results / "tracks.json");
  return stored;
}

int CheckAgainst(const StoredResults& stored, const formats::Tracks& tracks, const std::string& source,
                 const CheckArguments& arguments, std::optional<OutputFolder>& out,
                 const formats::ProvenanceRecord& provenance, bool* repaired) {
  const std::vector<std::string> exports =
      arguments.exports.empty() ? std::vector<std::string>{} : formats::ParseExportFormats(arguments.exports);
  const check::CheckInputs inputs{&stored.calibration, &stored.intrinsics, stored.unusable, &tracks, &stored.tracks,
                                  {}};
  check::CalibrationCheck result;
  try {
    result = check::CheckCalibration(inputs, arguments.options);
  } catch (const std::invalid_argument& error) {
    throw InputError(source + ": " + error.what());
  }
  for (const auto& [name, verdict] : result.cameras) {
    if (verdict.status == "not seen" || verdict.status == "unknown") {
      std::cerr << "camera " << name << " " << verdict.status << ": " << verdict.reason << "\n";
    }
  }
  const bool repair = out && result.trusted;
  if (repaired != nullptr) *repaired = repair;
  if (repair) {
    const check::Repair repaired =
        check::Repaired(inputs, result, registration::Options{}.weak_rotation_sigma_deg);
    formats::ProvenanceRecord record = provenance;
    record.command = arguments.command_line;
    record.intrinsics = formats::ProvenanceInput{(fs::path(arguments.results) / "intrinsics").string(), ""};
    record.model = stored.calibration.model;
    record.checked = formats::ProvenanceInput{arguments.results, ""};
    SaveResults(*out, repaired.calibration, repaired.intrinsics, repaired.tracks, repaired.tracks, exports,
                [&](const fs::path& staging) {
                  formats::WriteProvenance(staging, formats::ProvenanceDocument(record, out->path(),
                                                                                [](const std::string& line) {
                                                                                  std::cerr << line << "\n";
                                                                                }));
                  formats::AtomicWrite(staging / "check.json", check::CheckJson(result));
                });
  } else if (out) {
    out->Abort();
  }
  if (arguments.json) {
    std::cout << check::CheckJson(result);
  } else {
    std::cout << check::CheckTable(result) << "\n" << result.message;
    if (out && !repair) std::cout << " (" << arguments.out << " not written)";
    std::cout << "\n";
    if (repair) std::cout << "repaired results in " << arguments.out << "\n";
  }
  return check::CheckExitStatus(result, repair);
}

int RunCheck(const CheckArguments& arguments, Interrupts& interrupts) {
  if (!arguments.exports.empty()) formats::ParseExportFormats(arguments.exports);  // before anything is read
  RequireValidOptions(arguments.options);
  // Claimed before the inputs are read, as the Python command does.
  std::optional<OutputFolder> out;
  if (!arguments.out.empty()) {
    out.emplace(arguments.out, arguments.force, formats::kCalibrationFiles, &interrupts);
    out->Open();
  }
  const StoredResults stored = ReadStored(arguments.results);
  const formats::Tracks tracks = formats::ReadTracks(arguments.tracks);
  formats::ProvenanceRecord provenance;
  provenance.source = formats::ProvenanceInput{arguments.tracks, ""};
  return CheckAgainst(stored, tracks, arguments.tracks, arguments, out, provenance);
}

}  // namespace calibproj::app
