#pragma once
// Keyword options of the video, sync and ingest bindings, mapped onto the C++ option
// structs by name (unknown names are a ValueError listing the known ones).

#include <pybind11/pybind11.h>

#include <nlohmann/json.hpp>

#include <map>
#include <string>
#include <vector>

#include "calibproj/detect/marker_detector.h"
#include "calibproj/ingest/camera_ingest.h"
#include "calibproj/ingest/sequence_description.h"
#include "calibproj/sync/synchronise.h"
#include "knob_setter.h"

namespace calibproj::bindings {

// Sets one sync option by name; false when `key` is not a sync option.
bool SetSyncOption(sync::SyncOptions* o, const std::string& key, const pybind11::handle& value);

// Sets one ingest option by name (sync options included); false when unknown.
bool SetIngestOption(ingest::IngestOptions* o, const std::string& key, const pybind11::handle& value);

// Throws ValueError naming the first option that is not a finite number of a sane
// magnitude (limits::OptionChecker); the ingest's own Check() does this for its options.
void CheckSyncOptionValues(sync::SyncOptions& o);

// Per knob, in order, a Knob; calibproj.ingest.options.IngestOptions is
// made from the ingest's, which holds the sync's (but fixed_exposure, in seconds there).
std::vector<Knob> SyncOptionTable();
std::vector<Knob> IngestOptionTable();

// The ingest options of keyword arguments named as option_table() names them, with these
// detector options; ValueError for an unknown name.
ingest::IngestOptions IngestOptionsFromKwargs(const detect::ArucoOptions& aruco, const detect::AprilTagOptions& apriltag,
                                              const pybind11::kwargs& kwargs);

// One camera's ingest with its entry of detect_report.json (made once, where
// calibproj-native makes it), bound as _core.ingest.CameraIngestResult.
struct IngestResult {
  ingest::CameraIngestResult result;
  nlohmann::ordered_json report;
};

// One camera's ingest as calibproj.ingest.videos reads it (CameraIngest.raw).
pybind11::object BoundIngestResult(const ingest::CameraIngestResult& result,
                                   const ingest::SequenceDescription& sequence);

// Throws std::invalid_argument naming `key` and listing the names of `table`.
[[noreturn]] void ThrowUnknownOption(const std::string& what, const std::string& key, const std::vector<Knob>& table);

}  // namespace calibproj::bindings
