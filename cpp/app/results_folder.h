#pragma once
// A results folder as `calibrate` writes it, shared by the commands that write one
// (calibrate, check --out).

#include <filesystem>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "calibproj/formats/calibration.h"
#include "calibproj/formats/intrinsics_file.h"
#include "calibproj/formats/tracks_file.h"
#include "calibproj/formats/output_folder.h"

namespace calibproj::app {

// The results, the inputs they came from (tracks.json `given` and intrinsics/, as the
// Python command keeps them) and the exports (of `tracks`, the observations calibrated),
// written into the staging folder with what `extra` writes there, then moved into place.
void SaveResults(formats::OutputFolder& folder, const formats::Calibration& calibration,
                 const std::map<std::string, formats::CameraIntrinsics>& intrinsics, const formats::Tracks& given,
                 const formats::Tracks& tracks, const std::vector<std::string>& exports,
                 const std::function<void(const std::filesystem::path& staging)>& extra = {});

}  // namespace calibproj::app
