#pragma once
// Streaming decode of one video with FFmpeg's libraries (libavformat, libavcodec).
//
// Frames are visited once, in order: Grab() decodes the next frame (FFmpeg's frame
// threads, as many as SourceOptions says) and Gray() gives its luma only
// when asked. Camera videos are YUV: the luma plane is the grey image, so nothing is
// converted to colour and back (OpenCV's VideoCapture converts every retrieved frame
// to BGR). Limited-range ("TV", 16-235) luma is stretched to full range, so the grey
// image equals cv::cvtColor of the colour frame a player shows, up to rounding.

#include <opencv2/core.hpp>

#include "calibproj/video/luma.h"

#include <atomic>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace calibproj::video {

struct VideoInfo {
  std::string path;
  int width = 0;
  int height = 0;
  // Rate of the frame grid: estimated from the container timestamps of the first
  // frames (snapped to a rate the container declares when they agree), else declared.
  double fps = 0.0;
  double declared_fps = 0.0;  // the container's average frame rate
  bool timed = false;         // the container gives frame timestamps
  int frame_count = 0;        // as the container declares it (may be approximate)
};

// How a video is opened: a file (the default), or a live source that FFmpeg reads (a
// stream URL such as rtsp://, http://, udp://, or a device such as /dev/video0 with
// format "v4l2"), optionally recorded while it is read.
struct SourceOptions {
  bool live = false;
  // FFmpeg's input format ("v4l2", "mpegts", ...); empty: found from the URL or content.
  std::string format;
  // Options of FFmpeg's protocol or device (e.g. rtsp_transport=tcp, video_size=1280x720).
  std::map<std::string, std::string> ffmpeg_options;
  // A live source must give its first frames within open_timeout_s; one that then sends
  // nothing for stall_timeout_s has ended (end_reason() says so).
  double open_timeout_s = 10.0;
  double stall_timeout_s = 5.0;
  // Every packet of the video stream, as read (not re-encoded, timestamps kept), is
  // written to this Matroska file; empty: nothing recorded.
  std::string record_path;
  // FFmpeg's decoding threads; 0: its own choice, one per core (as `ffmpeg` decodes).
  int decode_threads = 0;
  // Set from another thread: reading ends at once, as at the end of the stream, blocking
  // network reads included.
  std::shared_ptr<std::atomic<bool>> stop = std::make_shared<std::atomic<bool>>(false);

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

class VideoReader {
 public:
  // Opens the video; throws std::runtime_error naming the file (or source) when it
  // cannot be opened, has no video stream FFmpeg decodes, or declares no frame size or
  // rate, and a live source that gives no frame within its open timeout.
  explicit VideoReader(const std::string& path, const SourceOptions& source = {});
  ~VideoReader();
  VideoReader(const VideoReader&) = delete;
  VideoReader& operator=(const VideoReader&) = delete;

  const VideoInfo& info() const { return info_; }

  // Decodes the next frame; false at the end of the stream (or where it is corrupt
  // beyond what the decoder skips).
  bool Grab();
  // Index of the last grabbed frame (0 for the first), -1 before the first Grab().
  int frame_index() const { return frame_index_; }
  // Container timestamp of the last grabbed frame in seconds (NaN when the container
  // gives none): the time base, unlike the decoding index, survives dropped frames.
  double timestamp() const { return timestamp_; }

  // The grabbed frame's full-range 8-bit luma, made at the first call for this frame.
  // The image owns its pixels: it stays valid after the next Grab(). Throws
  // std::runtime_error naming the file when the frame is not of the declared size.
  cv::Mat Gray();

  // The grabbed frame's luma for measuring it: the decoded plane itself where it is
  // 8-bit luma (no copy, valid until the next Grab), else the grey image.
  LumaPlane Luma();

  // Why Grab() returned false: "" at the end of the stream, else "stopped" or, for a
  // live source, "stalled: no data for N s".
  const std::string& end_reason() const;
  // Packets written to the recording so far (0 without one). The recording is
  // finished (readable to its last packet) when the reader is destroyed.
  long long recorded_packets() const;

 private:
  struct Decoder;
  void CheckFrameSize() const;  // throws for a frame of another size than the video's
  VideoInfo info_;
  std::unique_ptr<Decoder> decoder_;
  cv::Mat gray_;
  int frame_index_ = -1;
  int gray_index_ = -1;
  double timestamp_ = 0.0;
};

// Frame period (seconds) of a frame grid that the timestamps lie on, allowing for
// missing frames and jitter well under half a period: the median interval, refined by
// a line fit of the timestamps against their grid slots. Returns 0 when fewer than
// three distinct timestamps are given. `times` need not be sorted.
double EstimateFramePeriod(std::vector<double> times);

// Frame rate of that grid: the first of `declared` (rates the container states; 0 =
// none) within 0.2 % of 1 / period, else 1 / period; 0 when the times give no period.
double GridRate(const std::vector<double>& times, const std::vector<double>& declared);

// Reads the size, frame rate and declared frame count without decoding.
VideoInfo ProbeVideo(const std::string& path);

}  // namespace calibproj::video
