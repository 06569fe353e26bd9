#include "calibproj/video/video_reader.h"

#include <cmath>
#include <filesystem>
#include <stdexcept>

namespace calibproj::video {

VideoReader::VideoReader(const std::string& path) {
  info_.path = path;
  if (!std::filesystem::is_regular_file(path)) throw std::runtime_error(path + ": no such video file");
  if (!capture_.open(path, cv::CAP_FFMPEG) || !capture_.isOpened()) {
    throw std::runtime_error(path + ": cannot open the video (corrupt, truncated or not a video FFmpeg reads)");
  }
  info_.width = static_cast<int>(capture_.get(cv::CAP_PROP_FRAME_WIDTH));
  info_.height = static_cast<int>(capture_.get(cv::CAP_PROP_FRAME_HEIGHT));
  info_.fps = capture_.get(cv::CAP_PROP_FPS);
  const double count = capture_.get(cv::CAP_PROP_FRAME_COUNT);
  info_.frame_count = std::isfinite(count) && count > 0 ? static_cast<int>(std::lround(count)) : 0;
  if (info_.width <= 0 || info_.height <= 0) throw std::runtime_error(path + ": the video declares no frame size");
  if (!(info_.fps > 0.0) || !std::isfinite(info_.fps)) {
    throw std::runtime_error(path + ": the video declares no frame rate");
  }
}

bool VideoReader::Grab() {
  if (!capture_.grab()) return false;
  ++frame_index_;
  return true;
}

const cv::Mat& VideoReader::Colour() {
  if (frame_index_ < 0) throw std::logic_error("VideoReader::Colour() before Grab()");
  if (retrieved_index_ != frame_index_) {
    if (!capture_.retrieve(colour_) || colour_.empty()) {
      throw std::runtime_error(info_.path + ": frame " + std::to_string(frame_index_) + " cannot be decoded");
    }
    if (colour_.type() != CV_8UC3 || colour_.cols != info_.width || colour_.rows != info_.height) {
      throw std::runtime_error(info_.path + ": frame " + std::to_string(frame_index_) + " is " +
                               std::to_string(colour_.cols) + "x" + std::to_string(colour_.rows) + " " +
                               cv::typeToString(colour_.type()) + ", expected " + std::to_string(info_.width) +
                               "x" + std::to_string(info_.height) + " CV_8UC3");
    }
    retrieved_index_ = frame_index_;
  }
  return colour_;
}

VideoInfo ProbeVideo(const std::string& path) { return VideoReader(path).info(); }

}  // namespace calibproj::video
