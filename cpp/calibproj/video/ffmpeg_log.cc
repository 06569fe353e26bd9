#include "calibproj/video/ffmpeg_log.h"

extern "C" {
#include <libavdevice/avdevice.h>
#include <libavutil/log.h>
}

#include <cctype>
#include <cstdarg>
#include <mutex>

namespace calibproj::video {

namespace {

thread_local std::string last_ffmpeg_error;

void KeepError(void* context, int level, const char* format, va_list arguments) {
  if (level > AV_LOG_ERROR) return;
  char line[512];
  int print_prefix = 0;  // without FFmpeg's "[component @ 0x...]" prefix
  av_log_format_line2(context, level, format, arguments, line, sizeof line, &print_prefix);
  std::string text(line);
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back()))) text.pop_back();
  if (!text.empty()) last_ffmpeg_error = text;
}

}  // namespace

void KeepFfmpegErrors() {
  static std::once_flag once;
  std::call_once(once, [] {
    av_log_set_callback(KeepError);
    avdevice_register_all();  // cameras on this machine (v4l2) are sources too
  });
}

void ReclaimFfmpegLog() {
  KeepFfmpegErrors();
  av_log_set_callback(KeepError);
}

std::string FfmpegSaid() {
  std::string said;
  said.swap(last_ffmpeg_error);
  return said.empty() ? "" : "; FFmpeg: " + said;
}

}  // namespace calibproj::video
