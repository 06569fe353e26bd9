#pragma once
// FFmpeg's own messages do not reach the user's terminal: its last error on each thread
// is kept and named in the one error line of a video or source that cannot be read.

#include <string>

namespace calibproj::video {

// Installs the log callback (and FFmpeg's devices) once per process.
void KeepFfmpegErrors();
// Installs the log callback again: a library that sets its own (libmpv does, for the
// whole process) would otherwise print FFmpeg's messages on the terminal after it.
void ReclaimFfmpegLog();

// "; FFmpeg: <its last error on this thread>" (and forgets it), or "" when it said nothing.
std::string FfmpegSaid();

}  // namespace calibproj::video
