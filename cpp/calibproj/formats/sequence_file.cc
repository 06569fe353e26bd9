#include "calibproj/formats/sequence_file.h"

#include <stdexcept>
#include <string>
#include <vector>

#include "calibproj/formats/files.h"

namespace calibproj::formats {

namespace {

using nlohmann::json;

// The list at document[key] (json::out_of_range when it is missing).
const json& ListAt(const json& document, const char* key) {
  const json& list = document.at(key);
  if (!list.is_array()) throw std::invalid_argument(std::string(key) + ": expected a list");
  return list;
}

ingest::PatternSpec PatternFromJson(const json& p, const std::string& where) {
  ingest::PatternSpec pattern;
  pattern.array = IntValue(p.at("array"), where + ".array");
  pattern.scale_index = IntValue(p.at("scale_index"), where + ".scale_index");
  pattern.scale = NumberValue(p.at("scale"), where + ".scale");
  pattern.marker_side_px = NumberValue(p.at("marker_side_px"), where + ".marker_side_px");
  pattern.first_frame = IntValue(p.at("first_frame"), where + ".first_frame");
  pattern.last_frame = IntValue(p.at("last_frame"), where + ".last_frame");
  pattern.omitted = IntList(p.at("omitted"), where + ".omitted");
  return pattern;
}

sync::LightCode CodeFromJson(const json& c, const std::string& where) {
  sync::LightCode code;
  code.bits = IntList(c.at("bits"), where + ".bits");
  code.frames_per_bit = IntValue(c.at("frames_per_bit"), where + ".frames_per_bit");
  code.first_frame = IntValue(c.at("first_frame"), where + ".first_frame");
  return code;
}

// Centres are [array][marker][x, y]; every array has the same number of markers.
void ReadCentres(const json& document, ingest::SequenceDescription* s) {
  const json& centres = ListAt(document, "centres");
  s->arrays = static_cast<int>(centres.size());
  for (const json& array : centres) {
    if (!array.is_array()) throw std::invalid_argument("centres: expected a list of centres per array");
    if (&array == &centres[0]) s->markers_per_array = static_cast<int>(array.size());
    if (static_cast<int>(array.size()) != s->markers_per_array) {
      throw std::invalid_argument("every array needs the same number of centres");
    }
    for (const json& xy : array) {
      const std::vector<double> point = NumberList(xy, "centres");
      if (point.size() != 2) throw std::invalid_argument("centres must be [x, y] pairs");
      s->centres.emplace_back(point[0], point[1]);
    }
  }
}

ingest::SequenceDescription SequenceFromJson(const json& document) {
  ingest::SequenceDescription s;
  const json& markers = document.at("markers");
  const json& projector = document.at("projector");
  s.markers = StringValue(markers.at("spec"), "markers.spec");
  s.inverted = BoolValue(markers.at("inverted"), "markers.inverted");
  const std::vector<int> resolution = IntList(projector.at("resolution"), "projector.resolution");
  if (resolution.size() != 2) throw std::invalid_argument("projector resolution must be [width, height]");
  s.projector_width = resolution[0];
  s.projector_height = resolution[1];
  s.fps = NumberValue(projector.at("fps"), "projector.fps");
  s.scales = NumberList(document.at("layout").at("scales"), "layout.scales");
  s.marker_px = NumberValue(document.at("layout").at("marker_px"), "layout.marker_px");
  ReadCentres(document, &s);
  for (const json& p : ListAt(document, "patterns")) {
    s.patterns.push_back(PatternFromJson(p, "patterns[" + std::to_string(s.patterns.size()) + "]"));
  }
  for (const json& seg : ListAt(document, "segments")) {
    const std::string where = "segments[" + std::to_string(s.segments.size()) + "]";
    s.segments.push_back({StringValue(seg.at("kind"), where + ".kind"),
                          IntValue(seg.at("first_frame"), where + ".first_frame"),
                          IntValue(seg.at("last_frame"), where + ".last_frame")});
  }
  s.start_code = CodeFromJson(document.at("codes").at("start"), "codes.start");
  s.end_code = CodeFromJson(document.at("codes").at("end"), "codes.end");
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

}  // namespace calibproj::formats
