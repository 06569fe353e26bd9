#pragma once
// The mean luma of every frame of a video, in one decoding pass (for inspecting the
// light codes of a recording, and for tests).

#include <string>
#include <vector>

namespace calibproj::video {

// Mean linearised luma (see LumaMeter) per slot of the frame grid (frame_clock.h:
// NaN where the camera dropped a frame; use_timestamps false: one slot per decoded
// frame). Throws std::runtime_error naming the file when it cannot be opened or its
// timestamps jump by more than max_gap_s.
std::vector<double> ReadLumaSignal(const std::string& path, double gamma, int row_step, bool use_timestamps = true,
                                   double max_gap_s = 2.0);

// Container timestamp (seconds; NaN where none) of every decoded frame, in decoding order.
std::vector<double> ReadFrameTimestamps(const std::string& path);

}  // namespace calibproj::video
