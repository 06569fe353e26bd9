#pragma once
// Grey frames encoded (H.264 by libx264, through libavcodec) and sent as a live stream
// (MPEG-TS over UDP, or any output FFmpeg writes), each with the timestamp the caller
// gives: a camera of the virtual operating room, whose clock, jitter and dropped
// frames are its own.

#include <opencv2/core.hpp>

#include <memory>
#include <string>

namespace calibproj::video {

struct StreamOptions {
  std::string format = "mpegts";  // FFmpeg's output format
  int key_frame_interval = 15;    // frames between key frames (a late receiver waits at most this)
  int crf = 23;                   // x264 constant-rate factor
  // The camera's nominal frame rate. x264's rate control scales each frame's
  // complexity by its duration; without it, it takes the time base (1 us) as the
  // frame period and spends about 5 QP less quality than the crf asks.
  double fps = 30.0;
  std::string preset = "ultrafast";
};

class StreamWriter {
 public:
  // Opens the output; throws std::runtime_error naming the URL when it cannot.
  StreamWriter(const std::string& url, int width, int height, const StreamOptions& options = {});
  ~StreamWriter();
  StreamWriter(const StreamWriter&) = delete;
  StreamWriter& operator=(const StreamWriter&) = delete;

  // Encodes and sends a CV_8UC1 frame of the stream's size shown at `time_s` (seconds
  // from the stream's start, increasing by at least a microsecond from frame to frame).
  // Throws std::invalid_argument for a frame of another size or type or a time that does
  // not increase, std::runtime_error naming the URL when sending fails.
  void Write(const cv::Mat& gray, double time_s);
  // Flushes the encoder and ends the stream (also done by the destructor).
  void Close();

 private:
  struct Encoder;
  std::unique_ptr<Encoder> encoder_;
};

}  // namespace calibproj::video
