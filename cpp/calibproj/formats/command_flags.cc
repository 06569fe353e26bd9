#include "calibproj/formats/command_flags.h"

#include <stdexcept>

namespace calibproj::formats {

namespace {

constexpr const char* kScaleHelp =
    "metric scale from one measurement: camera-height:NAME=METRES, distance:CAM_A,CAM_B=METRES or "
    "marker-size:[ARRAY/MARKER=]METRES (default: arbitrary unit)";
constexpr const char* kExportHelp = "also write the calibration as yaml, colmap and/or anipose (comma-separated)";
constexpr const char* kIntrinsicsHelp = "folder of per-camera intrinsics files";
constexpr const char* kDetectorOptionHelp =
    "marker detector option as calibproj.detect_markers takes it, e.g. quad_decimate=2 (repeatable; default: the "
    "detector's defaults)";
constexpr const char* kExposureHelp =
    "known exposure time of one camera: with it a rolling shutter's readout is measured where the light codes "
    "alone leave it open (repeatable; default: --exposure-s for every camera, else estimated)";

std::vector<CommandFlag> MakeTable() {
  return {
      {"calibrate", "--tracks", "FILE", "tracks.json to calibrate from"},
      {"calibrate", "--intrinsics", "DIR", kIntrinsicsHelp},
      {"calibrate", "--out", "DIR", "results folder"},
      {"calibrate", "--force", "", "replace an existing results folder (the whole folder)"},
      {"calibrate", "--scale", "MEASUREMENT", kScaleHelp},
      {"calibrate", "--sequence", "FILE",
       "sequence.json of the projection: its projector pixels tie every centre to the floor (needed with videos, "
       "and by --scale marker-size)"},
      {"calibrate", "--merge", "RESULTS",
       "add the observations of an earlier calibration (its results folder or tracks.json): the new observations "
       "come from a projection planned by `calibproj generate --densify RESULTS`, and --sequence is that densified "
       "sequence.json; same intrinsics as RESULTS"},
      {"calibrate", "--export", "FORMATS", kExportHelp},
      {"calibrate", "--exposure", "CAMERA=SECONDS", kExposureHelp},
      {"calibrate", "--detector-option", "NAME=VALUE", kDetectorOptionHelp},
      {"calibrate", "--no-progress", "", "no progress bars"},
      {"calibrate", "--json", "", "print the per-camera summary as JSON"},
      {"calibrate", "--nominal-fov", "DEG",
       "with videos and --refine-intrinsics: a camera without an intrinsics file starts from a pinhole with this "
       "horizontal field of view (centred, no distortion)"},
      {"detect", "--sequence", "FILE", "sequence.json of the projection"},
      {"detect", "--intrinsics", "DIR", kIntrinsicsHelp},
      {"detect", "--out", "FILE", "tracks file to write (tracks.json)"},
      {"detect", "--force", "", "replace an existing --out"},
      {"detect", "--exposure", "CAMERA=SECONDS", kExposureHelp},
      {"detect", "--detector-option", "NAME=VALUE", kDetectorOptionHelp},
      {"detect", "--no-progress", "", "no progress display"},
      {"detect", "--json", "", "print the report as JSON instead of a table"},
      {"check", "--tracks", "FILE", "tracks.json of the check projection"},
      {"check", "--out", "DIR", "write the repaired results folder here"},
      {"check", "--force", "", "replace an existing --out folder (the whole folder)"},
      {"check", "--export", "FORMATS", "with --out: also write the repaired calibration as yaml, colmap and/or "
                                       "anipose (comma-separated)"},
      {"check", "--json", "", "print every camera's verdict as check.json has it"},
      {"capture", "--out", "DIR", "results folder (needed unless --check)"},
      {"capture", "--force", "", "replace an existing results folder (the whole folder)"},
      {"capture", "--recordings", "DIR",
       "where the cameras are recorded while the capture runs (default: RESULTS_DIR-recordings-<time> beside it); "
       "moved into RESULTS_DIR/recordings"},
      {"capture", "--check", "RESULTS",
       "check the calibration in RESULTS instead of calibrating (as check): --sequence is then the check "
       "projection of `calibproj generate --check RESULTS`; --out gets the repaired results (without --out: check "
       "only)"},
      {"capture", "--sequence", "FILE", "project this sequence.json instead of the site file's (its video: "
                                        "--projection)"},
      {"capture", "--projection", "VIDEO", "the video of --sequence (default: projection.mp4 beside it)"},
      {"capture", "--scale", "MEASUREMENT", kScaleHelp},
      {"capture", "--export", "FORMATS", kExportHelp},
      {"capture", "--no-progress", "", "no status lines while recording"},
      {"capture", "--json", "", "print the per-camera summary as JSON"},
  };
}

}  // namespace

const std::vector<CommandFlag>& SharedCommandFlags() {
  static const std::vector<CommandFlag> table = MakeTable();
  return table;
}

const CommandFlag& SharedFlag(const std::string& command, const std::string& name) {
  for (const CommandFlag& flag : SharedCommandFlags()) {
    if (flag.command == command && flag.name == name) return flag;
  }
  throw std::invalid_argument(command + " " + name + ": not a flag both tools take");
}

}  // namespace calibproj::formats
