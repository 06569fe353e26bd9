#pragma once
// The packets of one video stream written unchanged (not re-encoded, timestamps kept)
// into a Matroska file: what a live source delivered, kept for a later calibration.

#include <string>

struct AVFormatContext;
struct AVPacket;
struct AVStream;

namespace calibproj::video {

class PacketRecorder {
 public:
  // Creates `path` for packets of `source` (its codec parameters and time base); throws
  // std::runtime_error naming the path when it cannot be created or the codec cannot
  // be stored without re-encoding.
  PacketRecorder(const std::string& path, const AVStream& source);
  // Finishes the file (its index and duration); a file whose writer was killed before
  // is still readable up to its last packet.
  ~PacketRecorder();
  PacketRecorder(const PacketRecorder&) = delete;
  PacketRecorder& operator=(const PacketRecorder&) = delete;

  // Writes a packet of the source stream. Throws std::runtime_error naming the path when
  // the file cannot be written (a full disk); a packet whose timestamps the container
  // cannot take (out of order) is left out and counted.
  void Write(const AVPacket& packet);

  long long packets() const { return packets_; }
  long long left_out() const { return left_out_; }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  AVFormatContext* output_ = nullptr;
  int source_time_base_num_ = 0;
  int source_time_base_den_ = 1;
  long long packets_ = 0;
  long long left_out_ = 0;
};

}  // namespace calibproj::video
