#include "calibproj/formats/provenance.h"

#include <sys/stat.h>
#include <sys/utsname.h>

#include <array>
#include <chrono>
#include <ctime>
#include <fstream>
#include <stdexcept>
#include <type_traits>

#include "calibproj/formats/files.h"
#include "calibproj/registration/option_table.h"

extern "C" {
#include <libavutil/mem.h>
#include <libavutil/sha.h>
}

#ifndef CALIBPROJ_VERSION
#define CALIBPROJ_VERSION "0+unknown"
#endif

namespace calibproj::formats {

namespace fs = std::filesystem;

namespace {

// A UTC time as Python's datetime.isoformat(timespec="seconds") writes it.
std::string IsoUtc(std::time_t seconds) {
  std::tm utc{};
  gmtime_r(&seconds, &utc);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%S+00:00", &utc);
  return text;
}

// The machine as "System-release-machine" (uname), e.g. Linux-6.1.0-18-amd64-x86_64.
std::string PlatformName() {
  utsname name{};
  if (uname(&name) != 0) return "unknown";
  return std::string(name.sysname) + "-" + name.release + "-" + name.machine;
}

// The path made absolute and normalised, without a trailing separator (os.path.abspath).
fs::path Absolute(const fs::path& path) {
  fs::path absolute = fs::absolute(path).lexically_normal();
  if (!absolute.has_filename() && absolute.has_parent_path() && absolute != absolute.root_path()) {
    absolute = absolute.parent_path();
  }
  return absolute;
}

bool IsWithin(const fs::path& path, const fs::path& folder) {
  auto inner = path.begin();
  for (auto outer = folder.begin(); outer != folder.end(); ++outer, ++inner) {
    if (inner == path.end() || *inner != *outer) return false;
  }
  return true;
}

nlohmann::ordered_json InputEntry(const std::optional<ProvenanceInput>& input, const fs::path& folder,
                                  const std::function<void(const std::string&)>& warn) {
  if (!input) return nullptr;
  if (input->path.empty()) return input->given;
  return FileIdentity(input->path, folder, warn);
}

nlohmann::ordered_json OptionsEntry(const std::optional<registration::Options>& options) {
  if (!options) return nullptr;
  nlohmann::ordered_json entry = nlohmann::ordered_json::object();
  registration::VisitRegistrationOptions(*options, [&](const std::string& name, const auto& field, const std::string&) {
    using T = std::decay_t<decltype(field)>;
    if constexpr (std::is_enum_v<T>) {
      entry[name] = registration::ChoiceName(field);
    } else {
      entry[name] = field;
    }
  });
  return entry;
}

nlohmann::ordered_json ScaleEntry(const std::optional<ScaleSource>& scale) {
  if (!scale) return nullptr;
  nlohmann::ordered_json entry = {{"measurement", scale->measurement}};
  if (scale->metres_per_unit) entry["metres_per_unit"] = *scale->metres_per_unit;
  if (!scale->error.empty()) entry["error"] = scale->error;
  return entry;
}

template <typename T>
nlohmann::ordered_json OrNull(const std::optional<T>& value) {
  return value ? nlohmann::ordered_json(*value) : nlohmann::ordered_json(nullptr);
}

}  // namespace

const char* Version() { return CALIBPROJ_VERSION; }

std::string PathAsRecorded(const fs::path& path, const fs::path& folder) {
  const fs::path absolute = Absolute(path);
  const fs::path results = Absolute(folder);
  if (IsWithin(absolute, results.parent_path())) return absolute.lexically_relative(results).generic_string();
  return absolute.string();
}

std::string FileSha256(const fs::path& path) {
  std::ifstream stream(path, std::ios::binary);
  if (!stream) throw std::runtime_error("cannot be read");
  AVSHA* sha = av_sha_alloc();
  if (sha == nullptr || av_sha_init(sha, 256) != 0) {
    av_free(sha);
    throw std::runtime_error("no SHA-256 context");
  }
  std::vector<char> block(1 << 20);
  while (stream) {
    stream.read(block.data(), static_cast<std::streamsize>(block.size()));
    if (stream.gcount() > 0) {
      av_sha_update(sha, reinterpret_cast<const uint8_t*>(block.data()), static_cast<size_t>(stream.gcount()));
    }
  }
  const bool failed = stream.bad();
  std::array<uint8_t, 32> digest{};
  av_sha_final(sha, digest.data());
  av_free(sha);
  if (failed) throw std::runtime_error("read failed");
  static const char* kHex = "0123456789abcdef";
  std::string hex;
  for (const uint8_t byte : digest) {
    hex += kHex[byte >> 4];
    hex += kHex[byte & 15];
  }
  return hex;
}

nlohmann::ordered_json FileIdentity(const fs::path& path, const fs::path& folder,
                                    const std::function<void(const std::string&)>& warn) {
  nlohmann::ordered_json entry = {{"path", PathAsRecorded(path, folder)}};
  std::error_code error;
  if (!fs::is_regular_file(path, error)) return entry;
  struct stat status {};
  if (stat(path.c_str(), &status) != 0) return entry;
  const auto size = static_cast<std::uintmax_t>(status.st_size);
  entry["bytes"] = size;
  if (size > kMaxHashedBytes) {
    entry["modified"] = IsoUtc(status.st_mtime);
    return entry;
  }
  try {
    entry["sha256"] = FileSha256(path);
  } catch (const std::exception& problem) {
    if (warn) warn(path.string() + ": not identified in " + kProvenanceFile + " (" + problem.what() + ")");
  }
  return entry;
}

nlohmann::ordered_json ProvenanceDocument(const ProvenanceRecord& record, const fs::path& folder,
                                          const std::function<void(const std::string&)>& warn) {
  nlohmann::ordered_json document;
  document["created"] = IsoUtc(std::chrono::system_clock::to_time_t(std::chrono::system_clock::now()));
  document["calibproj"] = Version();
  document["command"] = OrNull(record.command);
  for (const auto& [name, value] : record.runtime) document[name] = value;
  document["platform"] = PlatformName();
  nlohmann::ordered_json videos = nlohmann::ordered_json::object();
  for (const auto& [camera, video] : record.videos) {
    videos[camera] = video.find("://") != std::string::npos ? nlohmann::ordered_json{{"source", video}}
                                                             : FileIdentity(video, folder, warn);
  }
  nlohmann::ordered_json inputs = {{"source", InputEntry(record.source, folder, warn)},
                                   {"sequence", InputEntry(record.sequence, folder, warn)},
                                   {"intrinsics", InputEntry(record.intrinsics, folder, warn)},
                                   {"videos", videos},
                                   {"merged", InputEntry(record.merged, folder, warn)}};
  if (record.checked) inputs["checked"] = InputEntry(record.checked, folder, warn);
  document["inputs"] = inputs;
  document["markers"] = OrNull(record.markers);
  document["model"] = OrNull(record.model);
  document["options"] = OptionsEntry(record.options);
  document["scale"] = ScaleEntry(record.scale);
  return document;
}

void WriteProvenance(const fs::path& staging, const nlohmann::ordered_json& document) {
  AtomicWrite(staging / kProvenanceFile, DumpSchemaJson("provenance", 1, document));
}

}  // namespace calibproj::formats
