#pragma once
// Where a results folder came from: provenance.json (calibproj.provenance/1), written by
// both tools. It records when and how the calibration was made (the command line, or a
// call of the Python API), with which version, from which inputs (paths as the folder
// records them, and the SHA-256 of the files), which markers, model and options, and
// where the metric scale came from, so that a report read months later can be traced
// back and the run repeated.

#include <cstdint>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "calibproj/registration/reconstruction.h"

namespace calibproj::formats {

constexpr const char* kProvenanceFile = "provenance.json";
// Files larger than this are identified by size and modification time only: hashing a
// folder of videos would cost as much as decoding them.
constexpr std::uintmax_t kMaxHashedBytes = 64ull * 1024 * 1024;

// The version both tools record (pyproject.toml's, given to the build by CMake).
const char* Version();

// How a results folder records an input's path: relative to the folder when the input
// lies beside it (under the folder's parent), so that the record survives when both are
// moved or renamed together; absolute otherwise (Python's path_as_recorded).
std::string PathAsRecorded(const std::filesystem::path& path, const std::filesystem::path& folder);

// {"path", "bytes", "sha256"} of a file ("modified", UTC, instead of the hash for files
// over kMaxHashedBytes), {"path"} for a folder or anything unreadable (`warn` told why).
nlohmann::ordered_json FileIdentity(const std::filesystem::path& path, const std::filesystem::path& folder,
                                    const std::function<void(const std::string&)>& warn = {});

// SHA-256 of a file's bytes, as lowercase hex; std::runtime_error when it cannot be read.
std::string FileSha256(const std::filesystem::path& path);

// One input of a calibration: a path (a file or folder, identified when the record is
// made) or what was given instead of one (an object in memory: "Tracks given in memory").
struct ProvenanceInput {
  std::string path;
  std::string given;
};

// Where the metric scale came from: the measurement, and its factor or why none applied.
struct ScaleSource {
  std::string measurement;
  std::optional<double> metres_per_unit;
  std::string error;
};

// What a tool knows of a calibration it writes; the rest (date, version, platform,
// file identities) is added when the document is made.
struct ProvenanceRecord {
  std::optional<std::vector<std::string>> command;  // none: a call of the Python API
  // What the front end adds of its own after the command (Python: its version).
  std::vector<std::pair<std::string, std::string>> runtime;
  std::optional<ProvenanceInput> source, sequence, intrinsics, merged, checked;
  std::vector<std::pair<std::string, std::string>> videos;  // camera -> video file or live source URL
  std::optional<std::string> markers, model;
  std::optional<registration::Options> options;
  std::optional<ScaleSource> scale;
};

// The body of provenance.json for a results folder that will finally be at `folder`.
nlohmann::ordered_json ProvenanceDocument(const ProvenanceRecord& record, const std::filesystem::path& folder,
                                          const std::function<void(const std::string&)>& warn = {});

// Writes `document` (ProvenanceDocument) as staging/provenance.json, atomically.
void WriteProvenance(const std::filesystem::path& staging, const nlohmann::ordered_json& document);

}  // namespace calibproj::formats
