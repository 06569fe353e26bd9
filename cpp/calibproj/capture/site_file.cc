#include "calibproj/capture/site_file.h"

#include <nlohmann/json.hpp>

#include <set>
#include <stdexcept>

#include "calibproj/formats/files.h"
#include "calibproj/formats/json_values.h"
#include "calibproj/ingest/camera_ingest.h"

namespace calibproj::capture {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// The object's keys must be among `known`: a misspelt key is an error, not a default.
void RequireKnownKeys(const json& object, const std::string& where, const std::set<std::string>& known) {
  if (!object.is_object()) throw std::invalid_argument(where + ": expected an object, got " + formats::Describe(object));
  for (const auto& [key, value] : object.items()) {
    if (known.count(key) == 0) throw std::invalid_argument(where + "." + key + ": unknown entry");
  }
}

// A path entry, relative to the site file's folder.
fs::path PathEntry(const json& value, const std::string& what, const fs::path& folder) {
  const std::string text = formats::StringValue(value, what);
  if (text.empty()) throw std::invalid_argument(what + ": empty path");
  const fs::path path(text);
  return path.is_absolute() ? path : folder / path;
}

double Seconds(const json& object, const std::string& key, const std::string& where, double fallback) {
  if (!object.contains(key)) return fallback;
  const double value = formats::NumberValue(object.at(key), where + "." + key);
  if (!(value > 0.0 && value <= 3600.0)) {
    throw std::invalid_argument(where + "." + key + ": must be in (0, 3600] seconds, got " +
                                formats::Describe(object.at(key)));
  }
  return value;
}

// A URL (scheme://...) or a device is given to FFmpeg as written; a file path is made
// relative to the site file.
std::string SourceOf(const std::string& text, const fs::path& folder) {
  if (text.find("://") != std::string::npos || text.rfind("/dev/", 0) == 0 || fs::path(text).is_absolute()) return text;
  return (folder / text).string();
}

SiteCamera CameraEntry(const std::string& name, const json& entry, const fs::path& folder) {
  const std::string where = "cameras." + name;
  RequireKnownKeys(entry, where, {"source", "intrinsics", "format", "options", "exposure_s", "open_timeout_s",
                                  "stall_timeout_s"});
  if (name.empty() || name.find_first_of("/\\") != std::string::npos || name == "." || name == "..") {
    throw std::invalid_argument(where + ": a camera name must be a file name (no slashes)");
  }
  SiteCamera camera;
  camera.name = name;
  if (!entry.contains("source")) throw std::invalid_argument(where + ".source: missing");
  const std::string source = formats::StringValue(entry.at("source"), where + ".source");
  if (source.empty()) throw std::invalid_argument(where + ".source: empty");
  camera.source = SourceOf(source, folder);
  if (!entry.contains("intrinsics")) throw std::invalid_argument(where + ".intrinsics: missing");
  camera.intrinsics = PathEntry(entry.at("intrinsics"), where + ".intrinsics", folder);
  camera.options.live = true;
  if (entry.contains("format")) camera.options.format = formats::StringValue(entry.at("format"), where + ".format");
  if (entry.contains("options")) {
    const json& options = entry.at("options");
    if (!options.is_object()) {
      throw std::invalid_argument(where + ".options: expected an object of FFmpeg options, got " +
                                  formats::Describe(options));
    }
    for (const auto& [key, value] : options.items()) {
      camera.options.ffmpeg_options[key] =
          value.is_number() ? value.dump() : formats::StringValue(value, where + ".options." + key);
    }
  }
  camera.options.open_timeout_s = Seconds(entry, "open_timeout_s", where, camera.options.open_timeout_s);
  camera.options.stall_timeout_s = Seconds(entry, "stall_timeout_s", where, camera.options.stall_timeout_s);
  if (entry.contains("exposure_s")) {
    camera.exposure_s = formats::NumberValue(entry.at("exposure_s"), where + ".exposure_s");
    if (!ingest::ValidKnownExposure(camera.exposure_s)) {
      throw std::invalid_argument(where + ".exposure_s: must be more than 0 and at most 1 s, got " +
                                  formats::Describe(entry.at("exposure_s")));
    }
  }
  camera.options.Check();
  return camera;
}

ProjectorOptions ProjectorEntry(const json& entry) {
  RequireKnownKeys(entry, "projector", {"display", "screen", "video_output", "timeout_s"});
  ProjectorOptions projector;
  if (entry.contains("display")) projector.display = formats::StringValue(entry.at("display"), "projector.display");
  if (entry.contains("screen")) {
    projector.screen = static_cast<int>(formats::IntegerValue(entry.at("screen"), "projector.screen", -1, 32));
  }
  if (entry.contains("video_output")) {
    projector.video_output = formats::StringValue(entry.at("video_output"), "projector.video_output");
  }
  projector.timeout_s = Seconds(entry, "timeout_s", "projector", projector.timeout_s);
  projector.Check();
  return projector;
}

Site SiteOf(const json& document, const fs::path& path) {
  RequireKnownKeys(document, "site", {"schema", "sequence", "projection", "projector", "cameras", "timeouts"});
  const fs::path folder = path.parent_path();
  Site site;
  site.path = path;
  if (!document.contains("sequence")) throw std::invalid_argument("sequence: missing");
  site.sequence = PathEntry(document.at("sequence"), "sequence", folder);
  site.projection = document.contains("projection") ? PathEntry(document.at("projection"), "projection", folder)
                                                    : site.sequence.parent_path() / "projection.mp4";
  if (document.contains("projector")) site.projector = ProjectorEntry(document.at("projector"));
  if (!document.contains("cameras")) throw std::invalid_argument("cameras: missing");
  const json& cameras = document.at("cameras");
  if (!cameras.is_object() || cameras.empty()) {
    throw std::invalid_argument("cameras: expected an object of cameras by name, got " + formats::Describe(cameras));
  }
  for (const auto& [name, entry] : cameras.items()) site.cameras.push_back(CameraEntry(name, entry, folder));
  if (document.contains("timeouts")) {
    const json& timeouts = document.at("timeouts");
    RequireKnownKeys(timeouts, "timeouts", {"ready_s", "end_s"});
    site.ready_s = Seconds(timeouts, "ready_s", "timeouts", site.ready_s);
    site.end_s = Seconds(timeouts, "end_s", "timeouts", site.end_s);
  }
  return site;
}

}  // namespace

Site ReadSite(const fs::path& path) {
  const json document = formats::ReadSchemaJson(path, "site", 1);
  try {
    return SiteOf(document, path);
  } catch (const std::invalid_argument& error) {
    throw formats::InputError(path.string() + ": " + error.what());
  }
}

formats::ProvenanceInput SiteIntrinsicsProvenance() {
  return formats::ProvenanceInput{"", "the site file's intrinsics files"};
}

}  // namespace calibproj::capture
