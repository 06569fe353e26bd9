#pragma once
// The mean luma of every frame of a video, in one decoding pass (for inspecting the
// light codes of a recording, and for tests).

#include <string>
#include <vector>

namespace calibproj::video {

// Mean linearised luma of each frame (see LumaMeter). Throws std::runtime_error
// naming the file when it cannot be opened.
std::vector<double> ReadLumaSignal(const std::string& path, double gamma, int row_step);

}  // namespace calibproj::video
