#pragma once
// Streaming decode of one video with OpenCV's FFmpeg backend.
//
// Frames are visited once, in order: Grab() decodes the next frame and Colour()
// converts it only when asked. OpenCV 4.6's FFmpeg backend ignores
// CAP_PROP_CONVERT_RGB and always converts to BGR in retrieve() (measured), so the
// saving comes from not retrieving frames nobody needs: decoding alone is what
// `ffmpeg -f null` does.

#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>

#include <string>

namespace calibproj::video {

struct VideoInfo {
  std::string path;
  int width = 0;
  int height = 0;
  double fps = 0.0;
  int frame_count = 0;  // as the container declares it (may be approximate)
};

class VideoReader {
 public:
  // Opens the video; throws std::runtime_error naming the file when it cannot be
  // opened or declares no frame size or frame rate.
  explicit VideoReader(const std::string& path);

  const VideoInfo& info() const { return info_; }

  // Decodes the next frame; false at the end of the stream (or where it is corrupt).
  bool Grab();
  // Index of the last grabbed frame (0 for the first), -1 before the first Grab().
  int frame_index() const { return frame_index_; }

  // The grabbed frame as 8-bit BGR, converted at the first call for this frame.
  // Throws std::runtime_error naming the file when the frame cannot be converted.
  const cv::Mat& Colour();

 private:
  VideoInfo info_;
  cv::VideoCapture capture_;
  cv::Mat colour_;
  int frame_index_ = -1;
  int retrieved_index_ = -1;
};

// Reads the size, frame rate and declared frame count without decoding.
VideoInfo ProbeVideo(const std::string& path);

}  // namespace calibproj::video
