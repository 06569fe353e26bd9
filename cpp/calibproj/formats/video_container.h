#pragma once

#include <filesystem>
#include <string>

namespace calibproj::formats {

// The container format a file's first bytes show ("MP4/MOV", "Matroska/WebM", "AVI",
// "MPEG-TS", "MPEG-PS"), or "" for anything else: a video given where a JSON file is
// expected (a camera's recording as tracks, projection.mp4 as the sequence) is named
// as such, whatever its file name.
std::string VideoContainerOf(const std::string& head);

// VideoContainerOf the file's first bytes ("" when it cannot be read).
std::string VideoContainerOfFile(const std::filesystem::path& path);

}  // namespace calibproj::formats
