#pragma once
// tracks.json (calibproj.tracks/1): per camera the undistorted pixels of the points it
// sees.

#include <filesystem>

#include "calibproj/formats/tracks.h"

namespace calibproj::formats {

Tracks ReadTracks(const std::filesystem::path& path);

// Writes tracks.json: the header indented,
// then per camera its point ids and pixels on one line each (every camera listed,
// those without observations with empty lists).
// Atomically; std::invalid_argument naming the file when the tracks are inconsistent or
// a pixel is not finite (JSON has no NaN), the file then untouched.
void WriteTracks(const std::filesystem::path& path, const Tracks& tracks);

}  // namespace calibproj::formats
