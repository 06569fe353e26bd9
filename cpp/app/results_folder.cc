#include "results_folder.h"

#include <iostream>

#include "calibproj/formats/export.h"
#include "calibproj/uncertainty/volume_map.h"

namespace calibproj::app {

using formats::OutputFolder;
namespace fs = std::filesystem;
using formats::CameraIntrinsics;
using formats::Tracks;

void SaveResults(OutputFolder& folder, const formats::Calibration& calibration,
                 const std::map<std::string, CameraIntrinsics>& intrinsics, const Tracks& given,
                 const Tracks& tracks, const std::vector<std::string>& exports,
                 const std::function<void(const fs::path& staging)>& extra) {
  folder.Write([&](const fs::path& staging) {
    if (extra) extra(staging);
    for (const auto& name : given.cameras) {
      if (intrinsics.count(name)) {
        formats::WriteIntrinsics(staging / "intrinsics" / (name + ".json"), intrinsics.at(name));
      }
    }
    formats::WriteTracks(staging / "tracks.json", given);
    formats::WriteCalibration(staging, calibration);
    uncertainty::WriteUncertainty(staging, calibration, intrinsics);
    std::vector<std::string> warnings;
    if (calibration.poses.empty() && !exports.empty()) {
      warnings.push_back("no camera registered: nothing exported");  // the failures in metrics.json say why
    } else {
      for (const auto& format : exports) formats::Export(calibration, format, staging, intrinsics, &tracks, &warnings);
    }
    for (const auto& warning : warnings) std::cerr << warning << "\n";
  });
  folder.Commit();
}


}  // namespace calibproj::app
