#pragma once
// `calibproj-native detect`: camera videos + sequence.json + intrinsics -> tracks.json
// and detect_report.json, with the same C++ ingest (calibproj::ingest::IngestCamera),
// options and messages as `calibproj detect`.

#include <CLI/CLI.hpp>
#include <memory>
#include <string>
#include <vector>

#include "calibproj/ingest/camera_ingest.h"
#include "interrupts.h"
#include "video_ingest.h"

namespace calibproj::app {

struct DetectArguments {
  std::string videos, sequence, intrinsics, out;
  bool json = false;
  bool force = false;  // replace an existing --out
  VideoIngestArguments ingest;
};

// Adds the subcommand and its options (one flag per ingest option, named and defaulted
// like the Python IngestOptions fields) to the app.
std::shared_ptr<DetectArguments> AddDetectCommand(CLI::App& app, CLI::App** command);

// 0 when at least one camera gave tracks, 1 when every camera failed. The tracks file
// and the report beside it are each written atomically (output_folder.h, OutputFile).
int RunDetect(const DetectArguments& arguments, Interrupts& interrupts);

}  // namespace calibproj::app
