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

struct Lister {
  py::dict out;
  template <typename T>
  void operator()(const char* name, const T& field, const char* /*help*/) {
    out[name] = field;
  }
};

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

py::dict SyncOptionDefaults() {
  sync::SyncOptions o;
  Lister lister;
  VisitSync(o, lister);
  return lister.out;
}

py::list IngestOptionTable() {
  ingest::IngestOptions o;
  py::list table;
  ingest::VisitIngestOptions(o, [&table](const char* name, const auto& field, const char* help) {
    py::dict entry;
    entry["name"] = name;
    entry["default"] = field;
    entry["help"] = help;
    table.append(entry);
  });
  return table;
}

py::dict IngestOptionDefaults() {
  ingest::IngestOptions o;
  Lister lister;
  ingest::VisitIngestOptions(o, lister);
  return lister.out;
}

void ThrowUnknownOption(const std::string& what, const std::string& key, const py::dict& known) {
  std::string names;
  for (const auto& item : known) names += (names.empty() ? "" : ", ") + std::string(py::str(item.first));
  throw std::invalid_argument(what + ": unknown option '" + key + "' (choose from " + names + ")");
}

}  // namespace calibproj::bindings
