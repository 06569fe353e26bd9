#include "calibproj/formats/sequence_file.h"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <tuple>
#include <utility>
#include <string>
#include <vector>

#include "calibproj/detect/marker_family.h"
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

// What sequence.json says beside the ingest's SequenceDescription, checked against it.
struct Layout {
  std::pair<int, int> grid;
  int arrays = 0;
  double margin_px = 0.0;
  int frames_per_pattern = 0;
  int frame_count = 0;
  int start_last_frame = 0;
  int end_last_frame = 0;
  int id_count = 0;  // the marker family's ids
};

// The marker family, checked against the geometry the file gives; returns its id count.
int ReadMarkers(const json& document, ingest::SequenceDescription* s) {
  const json& markers = Member(document, "", "markers");
  s->markers = String(markers, "markers", "spec");
  const std::string system = Choice(Member(markers, "markers", "system"), "markers/system", {"aruco", "apriltag"});
  const std::string family_name = String(markers, "markers", "family");
  const int grid_cells = Integer(markers, "markers", "grid_cells", 1);
  const int quad_cells = Integer(markers, "markers", "quad_cells", 1);
  const int id_count = markers.contains("id_count") ? Integer(markers, "markers", "id_count", 0) : 0;
  s->inverted = Bool(markers, "markers", "inverted");
  detect::MarkerFamily family;
  try {
    family = detect::ParseMarkerFamily(s->markers);
  } catch (const std::invalid_argument& error) {
    throw SchemaError("markers/spec", error.what());
  }
  // The drawn and detected squares follow from the family: a file that says otherwise
  // would be drawn by one tool and detected by another with different geometry.
  const detect::MarkerGeometry geometry = detect::GetMarkerGeometry(family);
  const auto require = [&](bool same, const std::string& key, const std::string& expected) {
    if (!same) {
      throw SchemaError("markers/" + key, Describe(markers.at(key)) + " does not match " + s->markers + " (" +
                                              expected + ")");
    }
  };
  require(system == family.SystemName(), "system", family.SystemName());
  require(family_name == family.name, "family", family.name);
  require(grid_cells == geometry.grid_cells, "grid_cells", std::to_string(geometry.grid_cells));
  require(quad_cells == geometry.quad_cells, "quad_cells", std::to_string(geometry.quad_cells));
  const int family_ids = detect::MarkerIdCount(family);
  if (markers.contains("id_count")) require(id_count == family_ids, "id_count", std::to_string(family_ids));
  return family_ids;
}

void ReadProjector(const json& document, ingest::SequenceDescription* s) {
  const json& projector = Member(document, "", "projector");
  std::tie(s->projector_width, s->projector_height) = CountPair(projector, "projector", "resolution");
  s->fps = Positive(projector, "projector", "fps");
}

Layout ReadLayout(const json& document, ingest::SequenceDescription* s) {
  const json& layout = Member(document, "", "layout");
  Layout out;
  out.grid = CountPair(layout, "layout", "grid");
  out.arrays = Integer(layout, "layout", "arrays", 1);
  const json& scales = List(layout, "layout", "scales", 1);
  for (size_t k = 0; k < scales.size(); ++k) s->scales.push_back(Positive(scales[k], Item("layout/scales", k)));
  s->marker_px = Positive(layout, "layout", "marker_px");
  out.margin_px = Number(layout, "layout", "margin_px");
  Bool(layout, "layout", "snap_to_pixels");
  if (Number(layout, "layout", "min_gap_modules") < 0.0) {
    throw SchemaError("layout/min_gap_modules", Describe(layout.at("min_gap_modules")) + " is negative");
  }
  Choice(Member(layout, "layout", "order"), "layout/order", {"array-major"});
  out.frames_per_pattern = Integer(document, "", "frames_per_pattern", 1);
  out.frame_count = Integer(document, "", "frame_count", 1);
  return out;
}

// Centres are [array][marker][x, y]; every array has the same number of markers.
void ReadCentres(const json& document, ingest::SequenceDescription* s) {
  const json& centres = List(document, "", "centres", 1);
  s->arrays = static_cast<int>(centres.size());
  for (size_t a = 0; a < centres.size(); ++a) {
    const json& array = centres[a];
    const std::string where = Item("centres", a);
    if (!array.is_array()) throw SchemaError(where, Describe(array) + " is not of type 'array'");
    if (array.empty()) throw SchemaError(where, "[] has fewer than 1 items");
    if (a == 0) s->markers_per_array = static_cast<int>(array.size());
    if (static_cast<int>(array.size()) != s->markers_per_array) {
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

const ingest::SegmentSpec& OnlySegment(const ingest::SequenceDescription& s, const std::string& kind) {
  const ingest::SegmentSpec* found = nullptr;
  int count = 0;
  for (const ingest::SegmentSpec& segment : s.segments) {
    if (segment.kind == kind) {
      found = &segment;
      ++count;
    }
  }
  Require(count == 1, "expected exactly one " + kind + " segment");
  return *found;
}

bool Close(double value, double expected) { return std::abs(value - expected) <= 1e-8 + 1e-5 * std::abs(expected); }

// What a schema cannot say: the parts of the sequence agree with each other. Runs
// after the ingest's own Check(), so frames and codes are within the limits.
void CheckConsistent(const ingest::SequenceDescription& s, const Layout& layout) {
  const double margin = layout.margin_px;
  Require(s.projector_width - 2.0 * margin > 0.0 && s.projector_height - 2.0 * margin > 0.0,
          "grid " + std::to_string(layout.grid.first) + "x" + std::to_string(layout.grid.second) + " with margin " +
              FormatNumber("%.1f", margin) + " px does not fit a " + std::to_string(s.projector_width) + "x" +
              std::to_string(s.projector_height) + " projector");
  const long long per_array = static_cast<long long>(layout.grid.first) * layout.grid.second;
  Require(s.arrays == layout.arrays && s.markers_per_array == per_array,
          "centres have shape (" + std::to_string(s.arrays) + ", " + std::to_string(s.markers_per_array) +
              ", 2), expected (" + std::to_string(layout.arrays) + ", " + std::to_string(per_array) +
              ", 2) (arrays, markers, 2)");
  Require(s.markers_per_array <= layout.id_count, std::to_string(s.markers_per_array) + " markers per array but " +
                                                      s.markers + " has only " + std::to_string(layout.id_count) +
                                                      " ids");
  Require(layout.frame_count == s.FrameCount(), "frame_count " + std::to_string(layout.frame_count) +
                                                    " differs from the segments' " + std::to_string(s.FrameCount()));
  const ingest::SegmentSpec& start = OnlySegment(s, "start_code");
  const ingest::SegmentSpec& end = OnlySegment(s, "end_code");
  const ingest::SegmentSpec& span = OnlySegment(s, "patterns");
  const auto check_code = [](const sync::LightCode& code, int file_last, const ingest::SegmentSpec& segment) {
    const int last = code.EndFrame() - 1;
    Require(file_last == last, segment.kind + " ends on frame " + std::to_string(file_last) + " but its " +
                                   std::to_string(code.bits.size()) + " bits of " +
                                   std::to_string(code.frames_per_bit) + " frames end on " + std::to_string(last));
    Require(segment.first_frame == code.first_frame && segment.last_frame == last,
            segment.kind + " spans frames " + std::to_string(code.first_frame) + ".." + std::to_string(last) +
                " but its segment " + std::to_string(segment.first_frame) + ".." + std::to_string(segment.last_frame));
  };
  check_code(s.start_code, layout.start_last_frame, start);
  check_code(s.end_code, layout.end_last_frame, end);
  Require(s.start_code.bits != s.end_code.bits, "start and end light codes must differ");
  Require(start.last_frame < span.first_frame && span.last_frame < end.first_frame,
          "expected the start code, then the patterns, then the end code");
  int previous_last = span.first_frame - 1;
  for (size_t i = 0; i < s.patterns.size(); ++i) {
    const ingest::PatternSpec& p = s.patterns[i];
    const std::string where = "pattern " + std::to_string(i);
    Require(p.first_frame > previous_last && p.last_frame <= span.last_frame,
            where + " (frames " + std::to_string(p.first_frame) + ".." + std::to_string(p.last_frame) +
                ") overlaps another pattern or leaves the patterns segment " + std::to_string(span.first_frame) +
                ".." + std::to_string(span.last_frame));
    const long long frames = static_cast<long long>(p.last_frame) - p.first_frame + 1;
    Require(frames == layout.frames_per_pattern, where + " lasts " + std::to_string(frames) +
                                                     " frames, expected frames_per_pattern = " +
                                                     std::to_string(layout.frames_per_pattern));
    Require(Close(p.scale, s.scales[p.scale_index]),
            where + ": scale " + PythonFloat(p.scale) + " (index " + std::to_string(p.scale_index) +
                ") is not the layout's scale " + PythonFloat(s.scales[p.scale_index]));
    const double side = s.marker_px * p.scale;
    Require(Close(p.marker_side_px, side), where + ": marker side " + PythonFloat(p.marker_side_px) +
                                               " px, expected " + PythonFloat(side) + " px at scale " +
                                               PythonFloat(p.scale));
    previous_last = p.last_frame;
  }
}

std::string WithoutPrefix(const std::string& message, const std::string& prefix) {
  return message.rfind(prefix, 0) == 0 ? message.substr(prefix.size()) : message;
}

}  // namespace

ingest::SequenceDescription SequenceFromDocument(const nlohmann::json& document) {
  RequireObject(document, "");
  ingest::SequenceDescription s;
  const int id_count = ReadMarkers(document, &s);
  ReadProjector(document, &s);
  Layout layout = ReadLayout(document, &s);
  layout.id_count = id_count;
  ReadCentres(document, &s);
  ReadScaleTable(document);
  ReadPatterns(document, &s);
  ReadSegments(document, &s);
  const json& codes = Member(document, "", "codes");
  layout.start_last_frame = ReadCode(codes, "start", &s.start_code);
  layout.end_last_frame = ReadCode(codes, "end", &s.end_code);
  try {
    s.Check();
  } catch (const std::invalid_argument& error) {
    throw std::invalid_argument(WithoutPrefix(error.what(), "sequence: "));
  }
  CheckConsistent(s, layout);
  return s;
}

SequenceFile ReadSequenceFile(const std::filesystem::path& path) {
  SequenceFile file;
  file.document = ReadSchemaJson(path, "sequence", 1);
  try {
    file.description = SequenceFromDocument(file.document);
  } catch (const SchemaError& error) {
    throw InputError(path.string() + ": invalid sequence file " + error.what());
  } catch (const std::invalid_argument& error) {
    throw InputError(path.string() + ": invalid sequence file: " + error.what());
  }
  return file;
}

ingest::SequenceDescription ReadSequence(const std::filesystem::path& path) {
  return ReadSequenceFile(path).description;
}

}  // namespace calibproj::formats
