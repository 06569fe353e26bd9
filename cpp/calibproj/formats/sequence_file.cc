#include "calibproj/formats/sequence_file.h"

#include <stdexcept>
#include <string>
#include <vector>

#include "calibproj/formats/files.h"
#include "calibproj/formats/json_values.h"

namespace calibproj::formats {

namespace {

using nlohmann::json;

// A problem at one place of the document, worded as the Python reader's schema check
// words it: "invalid sequence file at patterns/0: 'array' is a required property".
class SchemaError : public std::invalid_argument {
 public:
  SchemaError(const std::string& where, const std::string& message)
      : std::invalid_argument("at " + (where.empty() ? std::string("top level") : where) + ": " + message) {}
};

std::string Join(const std::string& where, const std::string& key) { return where.empty() ? key : where + "/" + key; }

const json& Member(const json& object, const std::string& where, const std::string& key) {
  if (!object.is_object()) throw SchemaError(where, Describe(object) + " is not of type 'object'");
  const auto found = object.find(key);
  if (found == object.end()) throw SchemaError(where, "'" + key + "' is a required property");
  return *found;
}

const json& List(const json& object, const std::string& where, const std::string& key) {
  const json& list = Member(object, where, key);
  if (!list.is_array()) throw SchemaError(Join(where, key), Describe(list) + " is not of type 'array'");
  return list;
}

// The typed readers of files.h, their message placed at the member's path.
template <typename Read>
auto Typed(const json& object, const std::string& where, const std::string& key, Read read) {
  const json& value = Member(object, where, key);
  try {
    return read(value, Join(where, key));
  } catch (const SchemaError&) {
    throw;
  } catch (const std::invalid_argument& error) {
    std::string message = error.what();
    const std::string prefix = Join(where, key) + ": ";
    if (message.rfind(prefix, 0) == 0) message = message.substr(prefix.size());
    throw SchemaError(Join(where, key), message);
  }
}

int Int(const json& o, const std::string& where, const std::string& key) { return Typed(o, where, key, IntValue); }
double Number(const json& o, const std::string& where, const std::string& key) {
  return Typed(o, where, key, NumberValue);
}

ingest::PatternSpec PatternFromJson(const json& p, const std::string& where) {
  ingest::PatternSpec pattern;
  pattern.array = Int(p, where, "array");
  pattern.scale_index = Int(p, where, "scale_index");
  pattern.scale = Number(p, where, "scale");
  pattern.marker_side_px = Number(p, where, "marker_side_px");
  pattern.first_frame = Int(p, where, "first_frame");
  pattern.last_frame = Int(p, where, "last_frame");
  pattern.omitted = Typed(p, where, "omitted", IntList);
  return pattern;
}

sync::LightCode CodeFromJson(const json& c, const std::string& where) {
  sync::LightCode code;
  code.bits = Typed(c, where, "bits", IntList);
  code.frames_per_bit = Int(c, where, "frames_per_bit");
  code.first_frame = Int(c, where, "first_frame");
  return code;
}

// Centres are [array][marker][x, y]; every array has the same number of markers.
void ReadCentres(const json& document, ingest::SequenceDescription* s) {
  const json& centres = List(document, "", "centres");
  s->arrays = static_cast<int>(centres.size());
  for (size_t a = 0; a < centres.size(); ++a) {
    const json& array = centres[a];
    const std::string where = "centres/" + std::to_string(a);
    if (!array.is_array()) throw SchemaError(where, Describe(array) + " is not of type 'array'");
    if (a == 0) s->markers_per_array = static_cast<int>(array.size());
    if (static_cast<int>(array.size()) != s->markers_per_array) {
      throw std::invalid_argument("every array needs the same number of centres");
    }
    for (size_t m = 0; m < array.size(); ++m) {
      const std::string at = where + "/" + std::to_string(m);
      std::vector<double> point;
      try {
        point = NumberList(array[m], at);
      } catch (const std::invalid_argument& error) {
        throw SchemaError(at, std::string(error.what()).substr(at.size() + 2));
      }
      if (point.size() != 2) throw SchemaError(at, Describe(array[m]) + " is not a pair [x, y]");
      s->centres.emplace_back(point[0], point[1]);
    }
  }
}

ingest::SequenceDescription SequenceFromJson(const json& document) {
  ingest::SequenceDescription s;
  const json& markers = Member(document, "", "markers");
  const json& projector = Member(document, "", "projector");
  const json& layout = Member(document, "", "layout");
  s.markers = Typed(markers, "markers", "spec", StringValue);
  s.inverted = Typed(markers, "markers", "inverted", BoolValue);
  const std::vector<int> resolution = Typed(projector, "projector", "resolution", IntList);
  if (resolution.size() != 2) {
    throw SchemaError("projector/resolution", Describe(projector.at("resolution")) + " is not [width, height]");
  }
  s.projector_width = resolution[0];
  s.projector_height = resolution[1];
  s.fps = Number(projector, "projector", "fps");
  s.scales = Typed(layout, "layout", "scales", NumberList);
  s.marker_px = Number(layout, "layout", "marker_px");
  ReadCentres(document, &s);
  const json& patterns = List(document, "", "patterns");
  for (size_t k = 0; k < patterns.size(); ++k) s.patterns.push_back(PatternFromJson(patterns[k], "patterns/" + std::to_string(k)));
  const json& segments = List(document, "", "segments");
  for (size_t k = 0; k < segments.size(); ++k) {
    const std::string where = "segments/" + std::to_string(k);
    s.segments.push_back({Typed(segments[k], where, "kind", StringValue), Int(segments[k], where, "first_frame"),
                          Int(segments[k], where, "last_frame")});
  }
  const json& codes = Member(document, "", "codes");
  s.start_code = CodeFromJson(Member(codes, "codes", "start"), "codes/start");
  s.end_code = CodeFromJson(Member(codes, "codes", "end"), "codes/end");
  s.Check();
  return s;
}

}  // namespace

ingest::SequenceDescription ReadSequence(const std::filesystem::path& path) {
  const json document = ReadSchemaJson(path, "sequence", 1);
  try {
    return SequenceFromJson(document);
  } catch (const SchemaError& error) {
    throw InputError(path.string() + ": invalid sequence file " + error.what());
  } catch (const std::invalid_argument& error) {
    throw InputError(path.string() + ": invalid sequence file: " + error.what());
  }
}

}  // namespace calibproj::formats
