#include "calibproj/video/video_reader.h"

#include "calibproj/common/limits.h"
#include "calibproj/video/ffmpeg_log.h"
#include "calibproj/video/recording.h"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/pixdesc.h>
#include <libswscale/swscale.h>
}

#include <opencv2/core.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <deque>
#include <filesystem>
#include <limits>
#include <stdexcept>

namespace calibproj::video {

namespace {

double Rate(AVRational r) { return r.num > 0 && r.den > 0 ? av_q2d(r) : 0.0; }

// Packets read ahead at opening for their timestamps (about 4 s at 30 fps).
constexpr int kPeekPackets = 120;
// A declared rate within this relative distance of the timestamps' rate is taken as
// exact (timestamps quantised by the time base or jittered give a nearby estimate).
constexpr double kRateSnap = 2e-3;

double Median(std::vector<double> values) {
  const auto middle = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return *middle;
}

// 8-bit luma in the first plane, one byte per pixel: the plane is the grey image.
bool LumaPlaneFirst(AVPixelFormat format) {
  const AVPixFmtDescriptor* d = av_pix_fmt_desc_get(format);
  if (d == nullptr || (d->flags & (AV_PIX_FMT_FLAG_RGB | AV_PIX_FMT_FLAG_PAL | AV_PIX_FMT_FLAG_BAYER |
                                   AV_PIX_FMT_FLAG_HWACCEL | AV_PIX_FMT_FLAG_FLOAT))) {
    return false;
  }
  const AVComponentDescriptor& y = d->comp[0];
  return y.plane == 0 && y.depth == 8 && y.step == 1 && y.offset == 0 && y.shift == 0;
}

bool FullRange(const AVFrame& frame) {
  switch (frame.format) {
    case AV_PIX_FMT_YUVJ420P:
    case AV_PIX_FMT_YUVJ422P:
    case AV_PIX_FMT_YUVJ444P:
    case AV_PIX_FMT_YUVJ440P:
    case AV_PIX_FMT_YUVJ411P:
      return true;
    case AV_PIX_FMT_GRAY8:
      return frame.color_range != AVCOL_RANGE_MPEG;
    default:
      return frame.color_range == AVCOL_RANGE_JPEG;
  }
}

}  // namespace

struct VideoReader::Decoder {
  AVFormatContext* format = nullptr;
  AVCodecContext* codec = nullptr;
  AVPacket* packet = nullptr;
  AVFrame* frame = nullptr;
  SwsContext* scaler = nullptr;
  int stream = -1;
  bool draining = false;
  std::deque<AVPacket*> peeked;  // read ahead at opening, decoded first
  SourceOptions source;
  std::unique_ptr<PacketRecorder> recorder;
  // A live read blocked past this moment is interrupted (FFmpeg polls Interrupted).
  std::chrono::steady_clock::time_point deadline = std::chrono::steady_clock::time_point::max();
  std::string end_reason;

  static int Interrupted(void* opaque) {
    Decoder& d = *static_cast<Decoder*>(opaque);
    if (d.source.stop && d.source.stop->load()) {
      d.end_reason = "stopped";
      return 1;
    }
    if (std::chrono::steady_clock::now() > d.deadline) {
      if (d.end_reason.empty()) d.end_reason = "stalled: no data for " + Seconds(d.source.stall_timeout_s);
      return 1;
    }
    return 0;
  }

  static std::string Seconds(double seconds) {
    char text[32];
    std::snprintf(text, sizeof text, "%g s", seconds);
    return text;
  }

  void ArmDeadline(double seconds) {
    if (!source.live) return;
    deadline = std::chrono::steady_clock::now() +
               std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(seconds));
  }

  // The next packet of any stream (recording those of the video stream); false at the
  // end of the stream, when stopped or stalled.
  bool Read(AVPacket* p, double timeout_s) {
    ArmDeadline(timeout_s);
    if (source.stop && source.stop->load()) {
      end_reason = "stopped";
      return false;
    }
    if (av_read_frame(format, p) < 0) return false;
    if (recorder && p->stream_index == stream) recorder->Write(*p);
    return true;
  }

  ~Decoder() {
    for (AVPacket* p : peeked) av_packet_free(&p);
    sws_freeContext(scaler);
    av_frame_free(&frame);
    av_packet_free(&packet);
    avcodec_free_context(&codec);
    avformat_close_input(&format);
  }

  // Feeds the decoder until it gives a frame; false at the end of the stream.
  bool Next() {
    while (true) {
      const int received = avcodec_receive_frame(codec, frame);
      if (received == 0) return true;
      if (received != AVERROR(EAGAIN) || draining) return false;
      if (!peeked.empty()) {
        av_packet_move_ref(packet, peeked.front());
        av_packet_free(&peeked.front());
        peeked.pop_front();
      } else if (!Read(packet, source.stall_timeout_s)) {
        // End of file (or unreadable from here on): flush the frames still inside.
        draining = true;
        avcodec_send_packet(codec, nullptr);
        continue;
      }
      if (packet->stream_index == stream) {
        const int sent = avcodec_send_packet(codec, packet);
        // A damaged packet is skipped, as ffmpeg does; anything else ends the stream.
        if (sent < 0 && sent != AVERROR_INVALIDDATA) {
          av_packet_unref(packet);
          return false;
        }
      }
      av_packet_unref(packet);
    }
  }

  // Reads the first packets of the video stream ahead; their timestamps in seconds.
  std::vector<double> PeekTimes() {
    std::vector<double> times;
    const double time_base = av_q2d(format->streams[stream]->time_base);
    while (static_cast<int>(peeked.size()) < kPeekPackets) {
      AVPacket* p = av_packet_alloc();
      if (p == nullptr) throw std::bad_alloc();
      if (!Read(p, peeked.empty() ? source.open_timeout_s : source.stall_timeout_s)) {
        av_packet_free(&p);
        break;
      }
      if (p->stream_index != stream) {
        av_packet_free(&p);
        continue;
      }
      const int64_t stamp = p->pts != AV_NOPTS_VALUE ? p->pts : p->dts;
      if (stamp != AV_NOPTS_VALUE) times.push_back(static_cast<double>(stamp) * time_base);
      peeked.push_back(p);
    }
    return times;
  }
};

VideoReader::VideoReader(const std::string& path, const SourceOptions& source)
    : decoder_(std::make_unique<Decoder>()) {
  source.Check();
  info_.path = path;
  if (!source.live && !std::filesystem::is_regular_file(path)) throw std::runtime_error(path + ": no such video file");
  KeepFfmpegErrors();
  Decoder& d = *decoder_;
  d.source = source;
  const auto unreadable = [&path, &d] {
    if (d.source.live) {
      const std::string why = d.end_reason == "stopped" ? "stopped while opening"
                              : !d.end_reason.empty()   ? "no answer within " + Decoder::Seconds(d.source.open_timeout_s)
                                                        : "not a stream FFmpeg reads";
      return std::runtime_error(path + ": cannot open the live source (" + why + FfmpegSaid() + ")");
    }
    return std::runtime_error(path + ": cannot open the video (corrupt, truncated or not a video FFmpeg reads" +
                              FfmpegSaid() + ")");
  };
  d.format = avformat_alloc_context();
  if (d.format == nullptr) throw std::bad_alloc();
  d.format->interrupt_callback = AVIOInterruptCB{&Decoder::Interrupted, &d};
  const AVInputFormat* input_format = nullptr;
  if (!source.format.empty()) {
    input_format = av_find_input_format(source.format.c_str());
    if (input_format == nullptr) {
      throw std::runtime_error(path + ": FFmpeg has no input format \"" + source.format + "\"");
    }
  }
  AVDictionary* ffmpeg_options = nullptr;
  for (const auto& [key, value] : source.ffmpeg_options) av_dict_set(&ffmpeg_options, key.c_str(), value.c_str(), 0);
  d.ArmDeadline(source.open_timeout_s);
  const int opened = avformat_open_input(&d.format, path.c_str(), input_format, &ffmpeg_options);
  const AVDictionaryEntry* unused = av_dict_get(ffmpeg_options, "", nullptr, AV_DICT_IGNORE_SUFFIX);
  const std::string unused_key = unused != nullptr ? unused->key : "";
  av_dict_free(&ffmpeg_options);
  if (opened < 0) throw unreadable();  // avformat_open_input freed the context
  if (!unused_key.empty()) {
    throw std::runtime_error(path + ": FFmpeg's source does not know the option \"" + unused_key + "\"");
  }
  if (avformat_find_stream_info(d.format, nullptr) < 0) throw unreadable();
  d.end_reason.clear();  // a probe cut short by the deadline that still found the stream is no end
  const AVCodec* codec = nullptr;
  d.stream = av_find_best_stream(d.format, AVMEDIA_TYPE_VIDEO, -1, -1, &codec, 0);
  if (d.stream < 0 || codec == nullptr) throw std::runtime_error(path + ": no video stream FFmpeg can decode");
  const AVStream* stream = d.format->streams[d.stream];
  d.codec = avcodec_alloc_context3(codec);
  d.packet = av_packet_alloc();
  d.frame = av_frame_alloc();
  if (d.codec == nullptr || d.packet == nullptr || d.frame == nullptr) throw std::bad_alloc();
  if (avcodec_parameters_to_context(d.codec, stream->codecpar) < 0) throw unreadable();
  d.codec->thread_count = source.decode_threads;
  d.codec->thread_type = FF_THREAD_FRAME | FF_THREAD_SLICE;
  if (avcodec_open2(d.codec, codec, nullptr) < 0) throw unreadable();
  FfmpegSaid();  // what it said while opening a video it then read is not this video's error

  info_.width = stream->codecpar->width;
  info_.height = stream->codecpar->height;
  if (info_.width <= 0 || info_.height <= 0) {
    // A live stream joined between key frames has not told its parameters yet.
    throw std::runtime_error(path + (source.live ? ": the stream sent no key frame with its frame size within " +
                                                       Decoder::Seconds(source.open_timeout_s)
                                                 : ": the video declares no frame size"));
  }
  if (!source.record_path.empty()) d.recorder = std::make_unique<PacketRecorder>(source.record_path, *stream);
  info_.declared_fps =
      Rate(stream->avg_frame_rate) > 0.0 ? Rate(stream->avg_frame_rate) : Rate(stream->r_frame_rate);
  const std::vector<double> first_times = d.PeekTimes();
  if (source.live && d.peeked.empty()) throw unreadable();
  info_.fps = GridRate(first_times, {Rate(stream->r_frame_rate), Rate(stream->avg_frame_rate)});
  info_.timed = info_.fps > 0.0;
  if (!info_.timed) info_.fps = info_.declared_fps;
  if (stream->nb_frames > 0) {
    info_.frame_count = static_cast<int>(stream->nb_frames);
  } else if (stream->duration > 0) {
    info_.frame_count = static_cast<int>(std::lround(stream->duration * av_q2d(stream->time_base) * info_.fps));
  }
  if (!(info_.fps > 0.0) || !std::isfinite(info_.fps)) {
    throw std::runtime_error(path + ": the video declares no frame rate");
  }
}

VideoReader::~VideoReader() = default;

const std::string& VideoReader::end_reason() const { return decoder_->end_reason; }

long long VideoReader::recorded_packets() const {
  return decoder_->recorder ? decoder_->recorder->packets() : 0;
}

void SourceOptions::Check() const {
  const auto require = [](bool ok, const std::string& message) {
    if (!ok) throw std::invalid_argument("source options: " + message);
  };
  require(open_timeout_s > 0.0 && open_timeout_s <= 3600.0, "open_timeout_s must be in (0, 3600]");
  require(stall_timeout_s > 0.0 && stall_timeout_s <= 3600.0, "stall_timeout_s must be in (0, 3600]");
  require(decode_threads >= 0 && decode_threads <= limits::kMaxThreads,
          "decode_threads must be in [0, " + std::to_string(limits::kMaxThreads) + "]");
  require(live || (format.empty() && ffmpeg_options.empty()), "a format and FFmpeg options are for live sources");
  for (const auto& [key, value] : ffmpeg_options) {
    require(!key.empty() && key.find('\0') == std::string::npos && value.find('\0') == std::string::npos,
            "FFmpeg option names must be non-empty text");
  }
}

bool VideoReader::Grab() {
  if (!decoder_->Next()) return false;
  ++frame_index_;
  const AVFrame& frame = *decoder_->frame;
  timestamp_ = frame.best_effort_timestamp == AV_NOPTS_VALUE
                   ? std::numeric_limits<double>::quiet_NaN()
                   : static_cast<double>(frame.best_effort_timestamp) *
                         av_q2d(decoder_->format->streams[decoder_->stream]->time_base);
  return true;
}

void VideoReader::CheckFrameSize() const {
  if (frame_index_ < 0) throw std::logic_error("VideoReader: a frame asked for before Grab()");
  const AVFrame& frame = *decoder_->frame;
  if (frame.width != info_.width || frame.height != info_.height) {
    throw std::runtime_error(info_.path + ": frame " + std::to_string(frame_index_) + " is " +
                             std::to_string(frame.width) + "x" + std::to_string(frame.height) + ", expected " +
                             std::to_string(info_.width) + "x" + std::to_string(info_.height));
  }
}

LumaPlane VideoReader::Luma() {
  CheckFrameSize();
  if (gray_index_ == frame_index_) return {gray_, false};
  const AVFrame& frame = *decoder_->frame;
  const auto format = static_cast<AVPixelFormat>(frame.format);
  if (!LumaPlaneFirst(format) || frame.linesize[0] <= 0) return {Gray(), false};
  const cv::Mat plane(frame.height, frame.width, CV_8UC1, frame.data[0], static_cast<size_t>(frame.linesize[0]));
  return {plane, !FullRange(frame)};
}

cv::Mat VideoReader::Gray() {
  CheckFrameSize();
  if (gray_index_ == frame_index_) return gray_;
  const AVFrame& frame = *decoder_->frame;
  const auto format = static_cast<AVPixelFormat>(frame.format);
  gray_ = cv::Mat();  // a new buffer: images handed out before keep theirs
  if (LumaPlaneFirst(format) && frame.linesize[0] > 0) {
    const cv::Mat luma(frame.height, frame.width, CV_8UC1, frame.data[0], static_cast<size_t>(frame.linesize[0]));
    gray_ = FullRangeGray({luma, !FullRange(frame)});
  } else {
    // RGB, paletted or deep formats: FFmpeg's scaler makes the grey image.
    decoder_->scaler = sws_getCachedContext(decoder_->scaler, frame.width, frame.height, format, frame.width,
                                            frame.height, AV_PIX_FMT_GRAY8, SWS_POINT, nullptr, nullptr, nullptr);
    if (decoder_->scaler == nullptr) {
      throw std::runtime_error(info_.path + ": frame " + std::to_string(frame_index_) + " is in pixel format " +
                               (av_get_pix_fmt_name(format) ? av_get_pix_fmt_name(format) : "unknown") +
                               ", which cannot be converted to grey");
    }
    gray_.create(frame.height, frame.width, CV_8UC1);
    uint8_t* planes[4] = {gray_.data, nullptr, nullptr, nullptr};
    int strides[4] = {static_cast<int>(gray_.step), 0, 0, 0};
    sws_scale(decoder_->scaler, frame.data, frame.linesize, 0, frame.height, planes, strides);
  }
  gray_index_ = frame_index_;
  return gray_;
}

VideoInfo ProbeVideo(const std::string& path) { return VideoReader(path).info(); }

double EstimateFramePeriod(std::vector<double> times) {
  times.erase(std::remove_if(times.begin(), times.end(), [](double t) { return !std::isfinite(t); }), times.end());
  std::sort(times.begin(), times.end());
  times.erase(std::unique(times.begin(), times.end()), times.end());
  if (times.size() < 3) return 0.0;
  std::vector<double> intervals(times.size() - 1);
  for (std::size_t i = 1; i < times.size(); ++i) intervals[i - 1] = times[i] - times[i - 1];
  // Most intervals are one period: the median is one (dropped frames make a few longer).
  const double median = Median(intervals);
  if (!(median > 0.0)) return 0.0;
  // Least-squares slope of time against grid slot; each slot is counted from the
  // previous frame's, so that the median's error does not accumulate over the frames.
  double ss = 0, st = 0, sss = 0, sst = 0, slot = 0;
  const double n = static_cast<double>(times.size());
  for (std::size_t i = 0; i < times.size(); ++i) {
    if (i > 0) slot += std::max(1.0, std::round(intervals[i - 1] / median));
    const double t = times[i] - times.front();
    ss += slot;
    st += t;
    sss += slot * slot;
    sst += slot * t;
  }
  const double denominator = n * sss - ss * ss;
  return denominator > 0.0 ? (n * sst - ss * st) / denominator : median;
}

double GridRate(const std::vector<double>& times, const std::vector<double>& declared) {
  const double period = EstimateFramePeriod(times);
  if (!(period > 0.0)) return 0.0;
  for (double rate : declared) {
    if (rate > 0.0 && std::abs(rate * period - 1.0) < kRateSnap) return rate;
  }
  return 1.0 / period;
}

}  // namespace calibproj::video
