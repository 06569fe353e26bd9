#include "sequence_file.h"

#include <stdexcept>
#include <string>
#include <vector>

#include "files.h"

namespace calibproj::app {

namespace {

using nlohmann::json;

ingest::PatternSpec PatternFromJson(const json& p) {
  ingest::PatternSpec pattern;
  pattern.array = p.at("array").get<int>();
  pattern.scale_index = p.at("scale_index").get<int>();
  pattern.scale = p.at("scale").get<double>();
  pattern.marker_side_px = p.at("marker_side_px").get<double>();
  pattern.first_frame = p.at("first_frame").get<int>();
  pattern.last_frame = p.at("last_frame").get<int>();
  pattern.omitted = p.at("omitted").get<std::vector<int>>();
  return pattern;
}

sync::LightCode CodeFromJson(const json& c) {
  sync::LightCode code;
  code.bits = c.at("bits").get<std::vector<int>>();
  code.frames_per_bit = c.at("frames_per_bit").get<int>();
  code.first_frame = c.at("first_frame").get<int>();
  return code;
}

// Centres are [array][marker][x, y]; every array has the same number of markers.
void ReadCentres(const json& document, ingest::SequenceDescription* s) {
  const auto centres = document.at("centres").get<std::vector<std::vector<std::vector<double>>>>();
  s->arrays = static_cast<int>(centres.size());
  s->markers_per_array = centres.empty() ? 0 : static_cast<int>(centres[0].size());
  for (const auto& array : centres) {
    if (static_cast<int>(array.size()) != s->markers_per_array) {
      throw std::invalid_argument("every array needs the same number of centres");
    }
    for (const auto& xy : array) {
      if (xy.size() != 2) throw std::invalid_argument("centres must be [x, y] pairs");
      s->centres.emplace_back(xy[0], xy[1]);
    }
  }
}

ingest::SequenceDescription SequenceFromJson(const json& document) {
  ingest::SequenceDescription s;
  const json& markers = document.at("markers");
  const json& projector = document.at("projector");
  s.markers = markers.at("spec").get<std::string>();
  s.inverted = markers.at("inverted").get<bool>();
  const auto resolution = projector.at("resolution").get<std::vector<int>>();
  if (resolution.size() != 2) throw std::invalid_argument("projector resolution must be [width, height]");
  s.projector_width = resolution[0];
  s.projector_height = resolution[1];
  s.fps = projector.at("fps").get<double>();
  s.scales = document.at("layout").at("scales").get<std::vector<double>>();
  ReadCentres(document, &s);
  for (const auto& p : document.at("patterns")) s.patterns.push_back(PatternFromJson(p));
  for (const auto& seg : document.at("segments")) {
    s.segments.push_back({seg.at("kind").get<std::string>(), seg.at("first_frame").get<int>(),
                          seg.at("last_frame").get<int>()});
  }
  s.start_code = CodeFromJson(document.at("codes").at("start"));
  s.end_code = CodeFromJson(document.at("codes").at("end"));
  s.Check();
  return s;
}

}  // namespace

ingest::SequenceDescription ReadSequence(const std::filesystem::path& path) {
  const json document = ReadSchemaJson(path, "sequence", 1);
  try {
    return SequenceFromJson(document);
  } catch (const json::exception& error) {
    throw InputError(path.string() + ": invalid sequence file: " + error.what());
  } catch (const std::invalid_argument& error) {
    throw InputError(path.string() + ": invalid sequence file: " + error.what());
  }
}

}  // namespace calibproj::app
