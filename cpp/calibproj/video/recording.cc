#include "calibproj/video/recording.h"

#include "calibproj/video/ffmpeg_log.h"

extern "C" {
#include <libavformat/avformat.h>
#include <libavutil/error.h>
}

#include <stdexcept>

namespace calibproj::video {

namespace {

std::string ErrorText(int code) {
  char text[AV_ERROR_MAX_STRING_SIZE] = {0};
  av_strerror(code, text, sizeof text);
  return text;
}

}  // namespace

PacketRecorder::PacketRecorder(const std::string& path, const AVStream& source)
    : path_(path), source_time_base_num_(source.time_base.num), source_time_base_den_(source.time_base.den) {
  const auto failed = [&path](const std::string& what, int code) {
    return std::runtime_error(path + ": cannot record the video (" + what + ": " + ErrorText(code) + FfmpegSaid() +
                              ")");
  };
  int code = avformat_alloc_output_context2(&output_, nullptr, "matroska", path.c_str());
  if (code < 0 || output_ == nullptr) throw failed("no Matroska muxer", code);
  AVStream* stream = avformat_new_stream(output_, nullptr);
  if (stream == nullptr) {
    avformat_free_context(output_);
    throw std::bad_alloc();
  }
  code = avcodec_parameters_copy(stream->codecpar, source.codecpar);
  stream->codecpar->codec_tag = 0;  // the container's own tag for the codec
  stream->time_base = source.time_base;
  // The source's frame rate (Matroska's default duration): read later, the recording
  // has the nominal rate the live stream had. Matroska's millisecond timestamps alone
  // made a 29.97 fps camera look like 30 fps; 0.1 % off over the projection moved the
  // frames picked per pattern onto the pattern changes, and every pattern was dropped.
  stream->avg_frame_rate = source.avg_frame_rate.num > 0 ? source.avg_frame_rate : source.r_frame_rate;
  stream->r_frame_rate = source.r_frame_rate;
  if (code >= 0) code = avio_open(&output_->pb, path.c_str(), AVIO_FLAG_WRITE);
  if (code < 0) {
    avformat_free_context(output_);
    throw failed("cannot create the file", code);
  }
  // Raw frames (a V4L2 camera's YUYV) are stored as Matroska's VfW-compatible raw video.
  AVDictionary* muxer_options = nullptr;
  av_dict_set(&muxer_options, "allow_raw_vfw", "1", 0);
  code = avformat_write_header(output_, &muxer_options);
  av_dict_free(&muxer_options);
  if (code < 0) {
    avio_closep(&output_->pb);
    avformat_free_context(output_);
    throw failed("the codec cannot be stored unchanged in Matroska", code);
  }
}

PacketRecorder::~PacketRecorder() {
  av_write_trailer(output_);
  avio_closep(&output_->pb);
  avformat_free_context(output_);
}

void PacketRecorder::Write(const AVPacket& packet) {
  AVPacket* copy = av_packet_clone(&packet);
  if (copy == nullptr) throw std::bad_alloc();
  av_packet_rescale_ts(copy, AVRational{source_time_base_num_, source_time_base_den_},
                       output_->streams[0]->time_base);
  copy->stream_index = 0;
  copy->pos = -1;
  const int code = av_interleaved_write_frame(output_, copy);  // takes the packet's data
  av_packet_free(&copy);
  if (code == AVERROR(EINVAL)) {
    ++left_out_;  // timestamps the container refuses (not increasing)
    return;
  }
  if (code < 0 || output_->pb->error < 0) {
    throw std::runtime_error(path_ + ": cannot write the recording (" +
                             ErrorText(code < 0 ? code : output_->pb->error) + ")");
  }
  ++packets_;
}

}  // namespace calibproj::video
