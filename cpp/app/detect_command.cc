#include "detect_command.h"

#include <algorithm>
#include <filesystem>
#include <iostream>
#include <vector>

#include "calibproj/formats/detect_report.h"
#include "calibproj/formats/files.h"
#include "calibproj/formats/output_folder.h"
#include "calibproj/formats/sequence_file.h"
#include "calibproj/formats/tracks_file.h"
#include "table_flags.h"

namespace calibproj::app {

using formats::AtomicWrite;
using formats::CameraOutcome;
using formats::DetectReport;
using formats::DumpSchemaJson;
using formats::FormatDetectReport;
using formats::OutputFile;
using formats::ReadSequence;
using formats::WriteTracks;

namespace fs = std::filesystem;

std::shared_ptr<DetectArguments> AddDetectCommand(CLI::App& app, CLI::App** command) {
  auto args = std::make_shared<DetectArguments>();
  CLI::App* cmd = app.add_subcommand(
      "detect",
      "Synchronise camera videos with the projection sequence and detect the MSMs: writes --out (tracks.json) and, "
      "next to it, its report (detect_report.json beside tracks.json, NAME.detect_report.json beside any other "
      "NAME.json). A camera that fails is reported; the others still give tracks. Exit status 1 "
      "when every camera failed.");
  cmd->add_option("videos", args->videos, "folder of camera videos (<camera>.mp4)")->required()->type_name("VIDEOS_DIR");
  SharedFlag(cmd, "--sequence", args->sequence)->required();
  SharedFlag(cmd, "--intrinsics", args->intrinsics)->required();
  SharedFlag(cmd, "--out", args->out)->required();
  SharedFlag(cmd, "--force", args->force);
  SharedFlag(cmd, "--json", args->json);
  AddVideoIngestFlags(cmd, &args->ingest);
  *command = cmd;
  return args;
}

int RunDetect(const DetectArguments& arguments, Interrupts& interrupts) {
  // Checked and locked before the inputs are read and the long ingest, as the Python
  // command does.
  OutputFile output(arguments.out, arguments.force, {arguments.sequence}, &interrupts);
  output.Open();
  const ingest::SequenceDescription sequence = ReadSequence(arguments.sequence);
  const std::vector<CameraOutcome> outcomes =
      IngestVideos(arguments.videos, arguments.intrinsics, sequence, arguments.ingest);

  const nlohmann::ordered_json report = DetectReport(outcomes, arguments.sequence, sequence);
  output.Write([&](const fs::path& out) {
    WriteTracks(out, formats::TracksOf(outcomes, sequence.markers_per_array));
    AtomicWrite(formats::DetectReportPath(arguments.out), DumpSchemaJson("detect_report", 1, report));
  });
  output.Close();
  std::cout << (arguments.json ? report.dump(1) : FormatDetectReport(report)) << "\n";
  const bool all_failed = std::none_of(outcomes.begin(), outcomes.end(), [](const auto& o) { return o.ok(); });
  return all_failed ? 1 : 0;
}

}  // namespace calibproj::app
