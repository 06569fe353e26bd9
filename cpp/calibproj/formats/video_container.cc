#include "calibproj/formats/video_container.h"

#include <fstream>
#include <iterator>

namespace calibproj::formats {

namespace {

// An MPEG transport stream is 188-byte packets, each starting with the sync byte 0x47.
constexpr size_t kTsPacket = 188;
constexpr size_t kHeadBytes = 3 * kTsPacket + 1;

bool StartsWith(const std::string& text, size_t at, const std::string& bytes) {
  return text.size() >= at + bytes.size() && text.compare(at, bytes.size(), bytes) == 0;
}

}  // namespace

std::string VideoContainerOf(const std::string& head) {
  if (StartsWith(head, 4, "ftyp")) return "MP4/MOV";  // ISO base media file format
  if (StartsWith(head, 0, std::string("\x1a\x45\xdf\xa3", 4))) return "Matroska/WebM";
  if (StartsWith(head, 0, "RIFF") && StartsWith(head, 8, "AVI ")) return "AVI";
  if (StartsWith(head, 0, std::string("\x00\x00\x01\xba", 4))) return "MPEG-PS";
  if (head.size() > 2 * kTsPacket && head[0] == '\x47' && head[kTsPacket] == '\x47' &&
      head[2 * kTsPacket] == '\x47') {
    return "MPEG-TS";
  }
  return "";
}

std::string VideoContainerOfFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::string head(kHeadBytes, '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<size_t>(in.gcount()));
  return VideoContainerOf(head);
}

}  // namespace calibproj::formats
