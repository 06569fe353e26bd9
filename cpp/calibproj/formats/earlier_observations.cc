#include "calibproj/formats/earlier_observations.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "calibproj/formats/files.h"

namespace calibproj::formats {

namespace fs = std::filesystem;

namespace {

bool Close(double a, double b) { return std::abs(a - b) <= 1e-9 * std::max({1.0, std::abs(a), std::abs(b)}); }

}  // namespace

bool SameIntrinsics(const CameraIntrinsics& a, const CameraIntrinsics& b) {
  for (int i = 0; i < 9; ++i) {
    if (!Close(a.K(i / 3, i % 3), b.K(i / 3, i % 3))) return false;
  }
  const size_t n = std::max(a.dist.size(), b.dist.size());
  for (size_t i = 0; i < n; ++i) {
    if (!Close(i < a.dist.size() ? a.dist[i] : 0.0, i < b.dist.size() ? b.dist[i] : 0.0)) return false;
  }
  return !(a.has_resolution && b.has_resolution) || (Close(a.width, b.width) && Close(a.height, b.height));
}

Tracks WithEarlierObservations(const fs::path& earlier, const Tracks& tracks,
                               const std::map<std::string, CameraIntrinsics>& intrinsics) {
  const bool folder = fs::is_directory(earlier);
  const fs::path file = folder ? earlier / "tracks.json" : earlier;
  if (folder && !fs::exists(file)) {
    throw InputError(earlier.string() + ": no tracks.json in it; give a results folder of calibproj calibrate or a "
                                        "tracks file");
  }
  const Tracks observed = ReadTracks(file);
  const fs::path used = earlier / "intrinsics";
  if (folder && fs::is_directory(used)) {
    const IntrinsicsDir stored = LoadIntrinsicsDir(used);
    for (const auto& name : observed.cameras) {
      const auto given = intrinsics.find(name);
      const auto then = stored.cameras.find(name);
      if (given == intrinsics.end() || then == stored.cameras.end()) continue;
      if (!SameIntrinsics(given->second, then->second)) {
        throw InputError((used / (name + ".json")).string() + ": camera " + name +
                         " was calibrated with other intrinsics than the ones given now; merge with the same "
                         "intrinsics (e.g. --intrinsics " + used.string() + ")");
      }
    }
  }
  try {
    return MergeTracks(observed, tracks);
  } catch (const std::invalid_argument& error) {
    throw InputError(file.string() + ": " + error.what());
  }
}

}  // namespace calibproj::formats
