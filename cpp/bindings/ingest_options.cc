// Keyword options of the video, sync and ingest bindings.

#include "ingest_options.h"

#include "calibproj/ingest/option_table.h"
#include "checks.h"
#include "knob_setter.h"

#include <stdexcept>

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

// The ingest takes the exposure in seconds (exposure_s), the bare sync in camera frames.
template <typename Options, typename Visitor>
void VisitSync(Options& o, Visitor&& visit) {
  ingest::VisitSyncOptions(o, visit);
  visit("fixed_exposure", o.fit.fixed_exposure, "known exposure, camera frames (0: fit it)");
}

}  // namespace

bool SetSyncOption(sync::SyncOptions* o, const std::string& key, const py::handle& value) {
  KnobSetter setter{key, value, "option '" + key + "'"};
  VisitSync(*o, setter);
  return setter.found;
}

bool SetIngestOption(ingest::IngestOptions* o, const std::string& key, const py::handle& value) {
  KnobSetter setter{key, value, "option '" + key + "'"};
  ingest::VisitIngestOptions(*o, setter);
  return setter.found;
}

void CheckSyncOptionValues(sync::SyncOptions& o) { VisitSync(o, limits::OptionChecker{"sync options: "}); }

std::vector<Knob> SyncOptionTable() {
  return KnobTable<sync::SyncOptions>([](auto& o, auto&& visit) { VisitSync(o, visit); });
}

std::vector<Knob> IngestOptionTable() {
  return KnobTable<ingest::IngestOptions>([](auto& o, auto&& visit) { ingest::VisitIngestOptions(o, visit); });
}

void ThrowUnknownOption(const std::string& what, const std::string& key, const std::vector<Knob>& table) {
  throw std::invalid_argument(what + ": unknown option '" + key + "' (choose from " + KnobNames(table) + ")");
}

}  // namespace calibproj::bindings
