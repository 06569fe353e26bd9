#pragma once
// A calibration in the formats of other tools (the Python module calibproj.formats.export
// documents each layout): calibration_opencv.yaml (cv::FileStorage), colmap/*.txt
// (COLMAP's text model) and calibration.toml (aniposelib). Only registered cameras are
// written, with world-to-camera poses in the floor frame.

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "calibproj/formats/calibration.h"
#include "calibproj/formats/intrinsics_file.h"
#include "calibproj/formats/tracks_file.h"

namespace calibproj::formats {

extern const std::vector<std::string> kExportFormats;  // yaml, colmap, anipose

// "yaml,colmap" -> {"yaml", "colmap"} (repeats dropped); std::invalid_argument naming an
// unknown format.
std::vector<std::string> ParseExportFormats(const std::string& text);

// Writes the calibration in `format` into `directory`; returns the files written.
// `tracks` (the calibration's, may be null) give COLMAP its 2D points and tracks.
// Cameras whose intrinsics give no image size get twice their principal point, with a
// line in `warnings`. std::invalid_argument when a registered camera has no intrinsics,
// nothing is registered, or a lens has no COLMAP model.
std::vector<std::filesystem::path> Export(const Calibration& calibration, const std::string& format,
                                          const std::filesystem::path& directory,
                                          const std::map<std::string, CameraIntrinsics>& intrinsics,
                                          const Tracks* tracks, std::vector<std::string>* warnings);

// COLMAP model and parameters of one camera (principal point shifted by half a pixel):
// PINHOLE without distortion, OPENCV with k1, k2, p1, p2 only, FULL_OPENCV with k3 or
// the rational terms; std::invalid_argument for thin-prism or tilt terms.
std::pair<std::string, std::vector<double>> ColmapCamera(const CameraIntrinsics& camera);

// Unit quaternion (w, x, y, z) of a rotation matrix, w >= 0.
Eigen::Vector4d QuaternionWxyz(const Eigen::Matrix3d& R);

}  // namespace calibproj::formats
