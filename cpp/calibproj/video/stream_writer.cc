#include "calibproj/video/stream_writer.h"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/error.h>
#include <libavutil/opt.h>
}

#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "calibproj/video/ffmpeg_log.h"

namespace calibproj::video {

namespace {

// Timestamps in microseconds: a camera's own clock, jitter included.
constexpr AVRational kTimeBase{1, 1000000};

std::string ErrorText(int code) {
  char text[AV_ERROR_MAX_STRING_SIZE] = {0};
  av_strerror(code, text, sizeof text);
  return text;
}

}  // namespace

struct StreamWriter::Encoder {
  std::string url;
  AVFormatContext* output = nullptr;
  AVCodecContext* codec = nullptr;
  AVFrame* frame = nullptr;
  AVPacket* packet = nullptr;
  AVStream* stream = nullptr;
  int64_t last_pts = std::numeric_limits<int64_t>::min();
  bool open = false;

  ~Encoder() {
    av_packet_free(&packet);
    av_frame_free(&frame);
    avcodec_free_context(&codec);
    if (output != nullptr) {
      if (output->pb != nullptr) avio_closep(&output->pb);
      avformat_free_context(output);
    }
  }

  std::runtime_error Failed(const std::string& what, int code) const {
    return std::runtime_error(url + ": cannot stream (" + what + ": " + ErrorText(code) + FfmpegSaid() + ")");
  }

  // Sends every packet the encoder has ready (`frame` null: flushes it).
  void Drain(const AVFrame* input) {
    int code = avcodec_send_frame(codec, input);
    if (code < 0 && code != AVERROR_EOF) throw Failed("encoding", code);
    while ((code = avcodec_receive_packet(codec, packet)) == 0) {
      av_packet_rescale_ts(packet, codec->time_base, stream->time_base);
      packet->stream_index = stream->index;
      code = av_interleaved_write_frame(output, packet);
      if (code < 0) throw Failed("sending", code);
    }
    if (code != AVERROR(EAGAIN) && code != AVERROR_EOF) throw Failed("encoding", code);
  }
};

StreamWriter::StreamWriter(const std::string& url, int width, int height, const StreamOptions& options)
    : encoder_(std::make_unique<Encoder>()) {
  if (width <= 0 || height <= 0 || width % 2 != 0 || height % 2 != 0 || width > 8192 || height > 8192) {
    throw std::invalid_argument("stream frames must be even sizes up to 8192, got " + std::to_string(width) + "x" +
                                std::to_string(height));
  }
  if (options.key_frame_interval < 1 || options.crf < 0 || options.crf > 51 || !(options.fps >= 1.0) ||
      !(options.fps <= 1000.0)) {
    throw std::invalid_argument(
        "stream options: key_frame_interval must be at least 1, crf in [0, 51] and fps in [1, 1000]");
  }
  KeepFfmpegErrors();
  Encoder& e = *encoder_;
  e.url = url;
  int code = avformat_alloc_output_context2(&e.output, nullptr, options.format.c_str(), url.c_str());
  if (code < 0 || e.output == nullptr) throw e.Failed("output format " + options.format, code);
  const AVCodec* h264 = avcodec_find_encoder_by_name("libx264");
  if (h264 == nullptr) throw std::runtime_error(url + ": cannot stream (FFmpeg has no libx264 encoder)");
  e.codec = avcodec_alloc_context3(h264);
  e.frame = av_frame_alloc();
  e.packet = av_packet_alloc();
  e.stream = avformat_new_stream(e.output, nullptr);
  if (e.codec == nullptr || e.frame == nullptr || e.packet == nullptr || e.stream == nullptr) throw std::bad_alloc();
  e.codec->width = width;
  e.codec->height = height;
  e.codec->pix_fmt = AV_PIX_FMT_YUV420P;  // what cameras send (the grey image in the luma plane)
  e.codec->color_range = AVCOL_RANGE_MPEG;
  e.codec->time_base = kTimeBase;
  e.codec->framerate = av_d2q(options.fps, 1000000);
  e.codec->gop_size = options.key_frame_interval;
  e.codec->max_b_frames = 0;
  e.codec->thread_count = 1;  // many cameras on few cores: one thread each
  if (e.output->oformat->flags & AVFMT_GLOBALHEADER) e.codec->flags |= AV_CODEC_FLAG_GLOBAL_HEADER;
  av_opt_set(e.codec->priv_data, "preset", options.preset.c_str(), 0);
  av_opt_set(e.codec->priv_data, "tune", "zerolatency", 0);
  av_opt_set_int(e.codec->priv_data, "crf", options.crf, 0);
  // Parameters before every key frame: a receiver that joins late can start there.
  av_opt_set(e.codec->priv_data, "x264-params", "repeat-headers=1", 0);
  if ((code = avcodec_open2(e.codec, h264, nullptr)) < 0) throw e.Failed("opening libx264", code);
  if ((code = avcodec_parameters_from_context(e.stream->codecpar, e.codec)) < 0) throw e.Failed("parameters", code);
  e.stream->time_base = kTimeBase;
  if (!(e.output->oformat->flags & AVFMT_NOFILE)) {
    if ((code = avio_open(&e.output->pb, url.c_str(), AVIO_FLAG_WRITE)) < 0) throw e.Failed("opening", code);
  }
  if ((code = avformat_write_header(e.output, nullptr)) < 0) throw e.Failed("writing the header", code);
  e.frame->format = AV_PIX_FMT_YUV420P;
  e.frame->width = width;
  e.frame->height = height;
  if ((code = av_frame_get_buffer(e.frame, 0)) < 0) throw e.Failed("frame buffer", code);
  e.open = true;
}

StreamWriter::~StreamWriter() {
  try {
    Close();
  } catch (const std::exception&) {
    // A receiver gone at the end is no error worth a crash in a destructor.
  }
}

void StreamWriter::Write(const cv::Mat& gray, double time_s) {
  Encoder& e = *encoder_;
  if (!e.open) throw std::logic_error("StreamWriter::Write after Close");
  if (gray.type() != CV_8UC1 || gray.cols != e.codec->width || gray.rows != e.codec->height) {
    throw std::invalid_argument("a stream frame must be 8-bit grey of " + std::to_string(e.codec->width) + "x" +
                                std::to_string(e.codec->height));
  }
  if (!std::isfinite(time_s) || std::abs(time_s) > 1e9) throw std::invalid_argument("frame time must be finite");
  const auto pts = static_cast<int64_t>(std::llround(time_s * 1e6));
  if (pts <= e.last_pts) throw std::invalid_argument("frame times must increase (by at least 1 us)");
  int code = av_frame_make_writable(e.frame);
  if (code < 0) throw e.Failed("frame buffer", code);
  // Full-range grey in a limited-range (TV) luma plane, as cameras encode; neutral chroma.
  for (int y = 0; y < gray.rows; ++y) {
    const uchar* in = gray.ptr<uchar>(y);
    uint8_t* out = e.frame->data[0] + static_cast<ptrdiff_t>(y) * e.frame->linesize[0];
    for (int x = 0; x < gray.cols; ++x) out[x] = static_cast<uint8_t>(16 + (in[x] * 219 + 127) / 255);
  }
  for (int plane = 1; plane <= 2; ++plane) {
    for (int y = 0; y < gray.rows / 2; ++y) {
      std::memset(e.frame->data[plane] + static_cast<ptrdiff_t>(y) * e.frame->linesize[plane], 128, gray.cols / 2);
    }
  }
  e.frame->pts = pts;
  e.last_pts = pts;
  e.Drain(e.frame);
}

void StreamWriter::Close() {
  Encoder& e = *encoder_;
  if (!e.open) return;
  e.open = false;
  e.Drain(nullptr);
  const int code = av_write_trailer(e.output);
  if (code < 0) throw e.Failed("ending", code);
}

}  // namespace calibproj::video
