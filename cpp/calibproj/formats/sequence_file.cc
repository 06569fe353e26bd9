#include "calibproj/formats/sequence_file.h"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <tuple>
#include <utility>
#include <string>
#include <vector>

#include "calibproj/common/limits.h"
#include "calibproj/formats/files.h"
#include "calibproj/formats/json_values.h"

namespace calibproj::formats {

namespace {

using nlohmann::json;

constexpr int kMaxInt = std::numeric_limits<int>::max();

// A problem at one place of the document: "invalid sequence file at patterns/0: 'array'
// is a required property".
class SchemaError : public std::invalid_argument {
 public:
  SchemaError(const std::string& where, const std::string& message)
      : std::invalid_argument("at " + (where.empty() ? std::string("top level") : where) + ": " + message) {}
};

std::string Join(const std::string& where, const std::string& key) { return where.empty() ? key : where + "/" + key; }

std::string Item(const std::string& where, size_t index) { return where + "/" + std::to_string(index); }

void RequireObject(const json& value, const std::string& where) {
  if (!value.is_object()) throw SchemaError(where, Describe(value) + " is not of type 'object'");
}

const json& Member(const json& object, const std::string& where, const std::string& key) {
  RequireObject(object, where);
  const auto found = object.find(key);
  if (found == object.end()) throw SchemaError(where, "'" + key + "' is a required property");
  return *found;
}

// A list of at least `min_items` entries.
const json& List(const json& object, const std::string& where, const std::string& key, size_t min_items) {
  const json& list = Member(object, where, key);
  if (!list.is_array()) throw SchemaError(Join(where, key), Describe(list) + " is not of type 'array'");
  if (list.size() < min_items) {
    throw SchemaError(Join(where, key), Describe(list) + " has fewer than " + std::to_string(min_items) + " items");
  }
  return list;
}

// The typed readers of json_values.h, their message placed at the value's path.
template <typename Read>
auto Typed(const json& value, const std::string& where, Read read) {
  try {
    return read(value, where);
  } catch (const SchemaError&) {
    throw;
  } catch (const std::invalid_argument& error) {
    std::string message = error.what();
    const std::string prefix = where + ": ";
    if (message.rfind(prefix, 0) == 0) message = message.substr(prefix.size());
    throw SchemaError(where, message);
  }
}

int Integer(const json& value, const std::string& where, int minimum) {
  return static_cast<int>(Typed(value, where, [minimum](const json& v, const std::string& w) {
    return IntegerValue(v, w, minimum, kMaxInt);
  }));
}

int Integer(const json& o, const std::string& where, const std::string& key, int minimum) {
  return Integer(Member(o, where, key), Join(where, key), minimum);
}

double Number(const json& o, const std::string& where, const std::string& key) {
  return Typed(Member(o, where, key), Join(where, key), NumberValue);
}

double Positive(const json& value, const std::string& where) {
  const double number = Typed(value, where, NumberValue);
  if (!(number > 0.0)) throw SchemaError(where, Describe(value) + " is not positive");
  return number;
}

double Positive(const json& o, const std::string& where, const std::string& key) {
  return Positive(Member(o, where, key), Join(where, key));
}

bool Bool(const json& o, const std::string& where, const std::string& key) {
  return Typed(Member(o, where, key), Join(where, key), BoolValue);
}

std::string String(const json& o, const std::string& where, const std::string& key) {
  return Typed(Member(o, where, key), Join(where, key), StringValue);
}

std::string Choice(const json& value, const std::string& where, const std::vector<std::string>& choices) {
  const std::string text = Typed(value, where, StringValue);
  for (const std::string& choice : choices) {
    if (text == choice) return text;
  }
  throw SchemaError(where, Describe(value) + " is not one of " + PythonList(choices));
}

// Two integers of at least 1: [width, height] or [rows, columns].
std::pair<int, int> CountPair(const json& o, const std::string& where, const std::string& key) {
  const json& pair = List(o, where, key, 2);
  if (pair.size() != 2) throw SchemaError(Join(where, key), Describe(pair) + " is not a pair of integers");
  return {Integer(pair[0], Item(Join(where, key), 0), 1), Integer(pair[1], Item(Join(where, key), 1), 1)};
}

// first_frame and last_frame of a frame range, both frames.
std::pair<int, int> FrameRange(const json& o, const std::string& where) {
  return {Integer(o, where, "first_frame", 0), Integer(o, where, "last_frame", 0)};
}

// What sequence.json repeats of the SequenceDescription, checked against it.
struct Repeated {
  int frame_count = 0;
  int start_last_frame = 0;
  int end_last_frame = 0;
  int centre_arrays = 0;  // the shape of the centres list
  int centres_per_array = 0;
};

// The marker family, checked against the geometry the file gives.
void ReadMarkers(const json& document, ingest::SequenceDescription* s) {
  const json& markers = Member(document, "", "markers");
  const std::string spec = String(markers, "markers", "spec");
  const std::string system = Choice(Member(markers, "markers", "system"), "markers/system", {"aruco", "apriltag"});
  const std::string family_name = String(markers, "markers", "family");
  const int grid_cells = Integer(markers, "markers", "grid_cells", 1);
  const int quad_cells = Integer(markers, "markers", "quad_cells", 1);
  const int id_count = markers.contains("id_count") ? Integer(markers, "markers", "id_count", 0) : 0;
  const bool inverted = Bool(markers, "markers", "inverted");
  try {
    s->markers = ingest::MarkerSystem::Of(spec, inverted);
  } catch (const std::invalid_argument& error) {
    throw SchemaError("markers/spec", error.what());
  }
  // The drawn and detected squares follow from the family: a file that says otherwise
  // would be drawn by one tool and detected by another with different geometry.
  const ingest::MarkerSystem& family = s->markers;
  const auto require = [&](bool same, const std::string& key, const std::string& expected) {
    if (!same) {
      throw SchemaError("markers/" + key, Describe(markers.at(key)) + " does not match " + spec + " (" +
                                              expected + ")");
    }
  };
  require(system == family.system, "system", family.system);
  require(family_name == family.family, "family", family.family);
  require(grid_cells == family.grid_cells, "grid_cells", std::to_string(family.grid_cells));
  require(quad_cells == family.quad_cells, "quad_cells", std::to_string(family.quad_cells));
  if (markers.contains("id_count")) require(id_count == family.id_count, "id_count", std::to_string(family.id_count));
}

void ReadProjector(const json& document, ingest::SequenceDescription* s) {
  const json& projector = Member(document, "", "projector");
  std::tie(s->projector_width, s->projector_height) = CountPair(projector, "projector", "resolution");
  s->fps = Positive(projector, "projector", "fps");
}

void ReadLayout(const json& document, ingest::SequenceDescription* s, Repeated* repeated) {
  const json& layout = Member(document, "", "layout");
  std::tie(s->grid_rows, s->grid_cols) = CountPair(layout, "layout", "grid");
  if (static_cast<long long>(s->grid_rows) * s->grid_cols > limits::kMaxPoints) {
    throw SchemaError("layout/grid", Describe(layout.at("grid")) + " has more than " +
                                         std::to_string(limits::kMaxPoints) + " markers per array");
  }
  s->arrays = Integer(layout, "layout", "arrays", 1);
  const json& scales = List(layout, "layout", "scales", 1);
  for (size_t k = 0; k < scales.size(); ++k) s->scales.push_back(Positive(scales[k], Item("layout/scales", k)));
  s->marker_px = Positive(layout, "layout", "marker_px");
  s->margin_px = Number(layout, "layout", "margin_px");
  s->snap_to_pixels = Bool(layout, "layout", "snap_to_pixels");
  s->min_gap_modules = Number(layout, "layout", "min_gap_modules");
  if (s->min_gap_modules < 0.0) {
    throw SchemaError("layout/min_gap_modules", Describe(layout.at("min_gap_modules")) + " is negative");
  }
  Choice(Member(layout, "layout", "order"), "layout/order", {"array-major"});
  s->frames_per_pattern = Integer(document, "", "frames_per_pattern", 1);
  repeated->frame_count = Integer(document, "", "frame_count", 1);
}

// Centres are [array][marker][x, y]; every array has the same number of markers.
void ReadCentres(const json& document, ingest::SequenceDescription* s, Repeated* repeated) {
  const json& centres = List(document, "", "centres", 1);
  repeated->centre_arrays = static_cast<int>(centres.size());
  for (size_t a = 0; a < centres.size(); ++a) {
    const json& array = centres[a];
    const std::string where = Item("centres", a);
    if (!array.is_array()) throw SchemaError(where, Describe(array) + " is not of type 'array'");
    if (array.empty()) throw SchemaError(where, "[] has fewer than 1 items");
    if (a == 0) repeated->centres_per_array = static_cast<int>(array.size());
    if (static_cast<int>(array.size()) != repeated->centres_per_array) {
      throw std::invalid_argument("every array needs the same number of centres");
    }
    for (size_t m = 0; m < array.size(); ++m) {
      const std::vector<double> point = Typed(array[m], Item(where, m), NumberList);
      if (point.size() != 2) throw SchemaError(Item(where, m), Describe(array[m]) + " is not a pair [x, y]");
      s->centres.emplace_back(point[0], point[1]);
    }
  }
}

// The marker sizes listed per scale: read for their types only (the patterns say what is drawn).
void ReadScaleTable(const json& document) {
  const json& scales = List(document, "", "scales", 1);
  for (size_t k = 0; k < scales.size(); ++k) {
    for (const char* key : {"scale", "marker_side_px", "module_px"}) Positive(scales[k], Item("scales", k), key);
  }
}

void ReadPatterns(const json& document, ingest::SequenceDescription* s) {
  const json& patterns = List(document, "", "patterns", 1);
  for (size_t k = 0; k < patterns.size(); ++k) {
    const json& p = patterns[k];
    const std::string where = Item("patterns", k);
    ingest::PatternSpec pattern;
    pattern.array = Integer(p, where, "array", 0);
    pattern.scale_index = Integer(p, where, "scale_index", 0);
    pattern.scale = Positive(p, where, "scale");
    pattern.marker_side_px = Positive(p, where, "marker_side_px");
    std::tie(pattern.first_frame, pattern.last_frame) = FrameRange(p, where);
    const json& omitted = List(p, where, "omitted", 0);
    for (size_t m = 0; m < omitted.size(); ++m) pattern.omitted.push_back(Integer(omitted[m], Item(where + "/omitted", m), 0));
    s->patterns.push_back(std::move(pattern));
  }
}

void ReadSegments(const json& document, ingest::SequenceDescription* s) {
  const json& segments = List(document, "", "segments", 1);
  for (size_t k = 0; k < segments.size(); ++k) {
    const std::string where = Item("segments", k);
    const auto [first, last] = FrameRange(segments[k], where);
    const std::string kind = Choice(Member(segments[k], where, "kind"), where + "/kind",
                                    {"white", "black", "start_code", "end_code", "patterns"});
    s->segments.push_back({kind, first, last});
  }
  if (document.contains("reference_frames")) {
    const json& references = document.at("reference_frames");
    RequireObject(references, "reference_frames");
    for (const char* kind : {"white", "black"}) {
      if (!references.contains(kind)) continue;
      const json& ranges = List(references, "reference_frames", kind, 0);
      for (size_t k = 0; k < ranges.size(); ++k) FrameRange(ranges[k], Item(Join("reference_frames", kind), k));
    }
  }
}

// A light code and the last frame the file gives for it.
int ReadCode(const json& codes, const std::string& key, sync::LightCode* code) {
  const std::string where = "codes/" + key;
  const json& c = Member(codes, "codes", key);
  const json& bits = List(c, where, "bits", 2);
  for (size_t k = 0; k < bits.size(); ++k) {
    const int bit = Integer(bits[k], Item(where + "/bits", k), 0);
    if (bit > 1) throw SchemaError(Item(where + "/bits", k), Describe(bits[k]) + " is not one of [0, 1]");
    code->bits.push_back(bit);
  }
  code->frames_per_bit = Integer(c, where, "frames_per_bit", 1);
  int last_frame = 0;
  std::tie(code->first_frame, last_frame) = FrameRange(c, where);
  return last_frame;
}

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument(message);
}

// The centres' shape is the layout's: (arrays, grid rows x columns, 2).
void CheckCentreShape(const ingest::SequenceDescription& s, const Repeated& repeated) {
  Require(repeated.centre_arrays == s.arrays && repeated.centres_per_array == s.markers_per_array,
          "centres have shape (" + std::to_string(repeated.centre_arrays) + ", " +
              std::to_string(repeated.centres_per_array) + ", 2), expected (" + std::to_string(s.arrays) + ", " +
              std::to_string(s.markers_per_array) + ", 2) (arrays, markers, 2)");
}

// What the file repeats agrees with the sequence (checked by then).
void CheckRepeated(const ingest::SequenceDescription& s, const Repeated& repeated) {
  Require(repeated.frame_count == s.FrameCount(), "frame_count " + std::to_string(repeated.frame_count) +
                                                      " differs from the segments' " + std::to_string(s.FrameCount()));
  const auto check_code = [](const sync::LightCode& code, int file_last, const char* kind) {
    const int last = code.EndFrame() - 1;
    Require(file_last == last, std::string(kind) + " ends on frame " + std::to_string(file_last) + " but its " +
                                   std::to_string(code.bits.size()) + " bits of " +
                                   std::to_string(code.frames_per_bit) + " frames end on " + std::to_string(last));
  };
  check_code(s.start_code, repeated.start_last_frame, "start_code");
  check_code(s.end_code, repeated.end_last_frame, "end_code");
}

std::string WithoutPrefix(const std::string& message, const std::string& prefix) {
  return message.rfind(prefix, 0) == 0 ? message.substr(prefix.size()) : message;
}

}  // namespace

ingest::SequenceDescription SequenceFromDocument(const nlohmann::json& document) {
  RequireObject(document, "");
  ingest::SequenceDescription s;
  Repeated repeated;
  ReadMarkers(document, &s);
  ReadProjector(document, &s);
  ReadLayout(document, &s, &repeated);
  s.markers_per_array = s.grid_rows * s.grid_cols;
  ReadCentres(document, &s, &repeated);
  ReadScaleTable(document);
  ReadPatterns(document, &s);
  ReadSegments(document, &s);
  const json& codes = Member(document, "", "codes");
  repeated.start_last_frame = ReadCode(codes, "start", &s.start_code);
  repeated.end_last_frame = ReadCode(codes, "end", &s.end_code);
  CheckCentreShape(s, repeated);
  try {
    s.Check();
  } catch (const std::invalid_argument& error) {
    throw std::invalid_argument(WithoutPrefix(error.what(), "sequence: "));
  }
  CheckRepeated(s, repeated);
  return s;
}

ingest::SequenceDescription ReadSequence(const std::filesystem::path& path) {
  const nlohmann::json document = ReadSchemaJson(path, "sequence", 1);
  try {
    return SequenceFromDocument(document);
  } catch (const SchemaError& error) {
    throw InputError(path.string() + ": invalid sequence file " + error.what());
  } catch (const std::invalid_argument& error) {
    throw InputError(path.string() + ": invalid sequence file: " + error.what());
  }
}

nlohmann::ordered_json SequenceDocument(const ingest::SequenceDescription& s) {
  using ordered = nlohmann::ordered_json;
  const auto range = [](int first, int last) { return ordered{{"first_frame", first}, {"last_frame", last}}; };
  const ingest::MarkerSystem& m = s.markers;
  ordered document;
  document["markers"] = {{"spec", m.spec}, {"system", m.system}, {"family", m.family},
                         {"grid_cells", m.grid_cells}, {"quad_cells", m.quad_cells}, {"id_count", m.id_count},
                         {"inverted", m.inverted}};
  document["projector"] = {{"resolution", {s.projector_width, s.projector_height}}, {"fps", s.fps}};
  document["layout"] = {{"grid", {s.grid_rows, s.grid_cols}}, {"arrays", s.arrays}, {"scales", s.scales},
                        {"marker_px", s.marker_px}, {"margin_px", s.margin_px},
                        {"snap_to_pixels", s.snap_to_pixels}, {"min_gap_modules", s.min_gap_modules},
                        {"order", "array-major"}};
  document["frames_per_pattern"] = s.frames_per_pattern;
  document["frame_count"] = s.FrameCount();
  document["duration_s"] = s.DurationS();
  ordered centres = ordered::array();
  for (int a = 0; a < s.arrays; ++a) {
    ordered array = ordered::array();
    for (int k = 0; k < s.markers_per_array; ++k) {
      const cv::Point2d& c = s.centres[static_cast<size_t>(a) * s.markers_per_array + k];
      array.push_back({c.x, c.y});
    }
    centres.push_back(std::move(array));
  }
  document["centres"] = std::move(centres);
  ordered scales = ordered::array();
  for (const double scale : s.scales) {
    const double side = s.marker_px * scale;
    scales.push_back({{"scale", scale}, {"marker_side_px", side}, {"module_px", side / m.grid_cells}});
  }
  document["scales"] = std::move(scales);
  ordered patterns = ordered::array();
  for (const ingest::PatternSpec& p : s.patterns) {
    patterns.push_back({{"array", p.array}, {"scale_index", p.scale_index}, {"scale", p.scale},
                        {"marker_side_px", p.marker_side_px}, {"first_frame", p.first_frame},
                        {"last_frame", p.last_frame}, {"omitted", p.omitted}});
  }
  document["patterns"] = std::move(patterns);
  const auto code = [](const sync::LightCode& c) {
    return ordered{{"bits", c.bits}, {"frames_per_bit", c.frames_per_bit}, {"first_frame", c.first_frame},
                   {"last_frame", c.EndFrame() - 1}};
  };
  document["codes"] = {{"start", code(s.start_code)}, {"end", code(s.end_code)}};
  ordered references = {{"white", ordered::array()}, {"black", ordered::array()}};
  ordered segments = ordered::array();
  for (const ingest::SegmentSpec& segment : s.segments) {
    if (segment.kind == "white" || segment.kind == "black") {
      references[segment.kind].push_back(range(segment.first_frame, segment.last_frame));
    }
    segments.push_back({{"kind", segment.kind}, {"first_frame", segment.first_frame},
                        {"last_frame", segment.last_frame}});
  }
  document["reference_frames"] = std::move(references);
  document["segments"] = std::move(segments);
  return document;
}

void WriteSequence(const std::filesystem::path& path, const ingest::SequenceDescription& sequence) {
  try {
    sequence.Check();
  } catch (const std::invalid_argument& error) {
    throw InputError(path.string() + ": cannot write the sequence file: " +
                     WithoutPrefix(error.what(), "sequence: "));
  }
  AtomicWrite(path, DumpSchemaJson("sequence", 1, SequenceDocument(sequence)));
}

}  // namespace calibproj::formats
