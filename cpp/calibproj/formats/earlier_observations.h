#pragma once
// Observations of an earlier projection, merged with a new one (calibrate --merge): the
// tracks.json of a results folder (or a tracks file), checked to have been undistorted
// with the intrinsics the new calibration uses and to share no point id with the new
// observations (a densified sequence shows only arrays the first one lacks).

#include <filesystem>
#include <map>
#include <string>

#include "calibproj/formats/intrinsics_file.h"
#include "calibproj/formats/tracks_file.h"

namespace calibproj::formats {

// `tracks` with the observations of `earlier` (a results folder or a tracks.json) added.
// InputError naming the file: unreadable tracks, a camera whose intrinsics in
// <earlier>/intrinsics/ differ from `intrinsics` (its pixels were undistorted with
// other ones), or point ids in both.
Tracks WithEarlierObservations(const std::filesystem::path& earlier, const Tracks& tracks,
                               const std::map<std::string, CameraIntrinsics>& intrinsics);

// True when both describe the same camera model (K, distortion with missing
// coefficients as zeros, image size) to 1e-9 relative.
bool SameIntrinsics(const CameraIntrinsics& a, const CameraIntrinsics& b);

}  // namespace calibproj::formats
