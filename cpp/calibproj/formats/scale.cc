#include "calibproj/formats/scale.h"

#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

#include "calibproj/formats/files.h"

namespace calibproj::formats {

namespace {

const std::vector<std::pair<std::string, std::string>> kForms = {
    {"camera-height", "camera-height:NAME=METRES"},
    {"marker-size", "marker-size:[ARRAY/MARKER=]METRES"},
    {"distance", "distance:CAM_A,CAM_B=METRES"}};

std::string Syntax() {
  std::string out;
  for (const auto& [kind, form] : kForms) out += (out.empty() ? "" : ", ") + form;
  return out;
}

std::string FormOf(const std::string& kind) {
  for (const auto& [name, form] : kForms) {
    if (name == kind) return form;
  }
  return "";
}

double ParseMetres(const std::string& where, const std::string& value) {
  const std::string text = Trimmed(value);
  double metres = 0.0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), metres);
  const bool infinite = error == std::errc::result_out_of_range && end == text.data() + text.size();
  if (infinite) metres = HUGE_VAL;
  if (text.empty() || (error != std::errc() && !infinite) || end != text.data() + text.size()) {
    throw std::invalid_argument(where + ": " + PythonRepr(text) + " is not a length in metres");
  }
  if (!(std::isfinite(metres) && metres > 0)) {
    throw std::invalid_argument(where + ": the length must be a positive number of metres, got " + PythonRepr(text));
  }
  return metres;
}

std::vector<std::string> ParseCameras(const std::string& where, const std::string& kind, const std::string& subject) {
  if (kind == "camera-height") {
    const std::string name = Trimmed(subject);
    if (name.empty()) throw std::invalid_argument(where + ": no camera name (expected camera-height:NAME=METRES)");
    return {name};
  }
  std::vector<std::string> names;
  size_t start = 0;
  for (size_t comma = subject.find(','); ; comma = subject.find(',', start)) {
    names.push_back(Trimmed(subject.substr(start, comma == std::string::npos ? std::string::npos : comma - start)));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  if (names.size() != 2 || names[0].empty() || names[1].empty()) {
    throw std::invalid_argument(where + ": expected two cameras CAM_A,CAM_B before '=', got " + PythonRepr(subject));
  }
  if (names[0] == names[1]) {
    throw std::invalid_argument(where + ": a distance needs two different cameras, got " + PythonRepr(names[0]) +
                                " twice");
  }
  return names;
}

// "ARRAY/MARKER" with optional spaces; indices beyond long long saturate (and then
// name no marker of any sequence).
std::optional<std::pair<long long, long long>> ParseMarker(const std::string& where, const std::string& subject) {
  const auto bad = [&] {
    return std::invalid_argument(where + ": the marker must be ARRAY/MARKER (two indices from 0), got " +
                                 PythonRepr(subject));
  };
  const size_t slash = subject.find('/');
  if (slash == std::string::npos) throw bad();
  long long index[2];
  const std::string parts[2] = {Trimmed(subject.substr(0, slash)), Trimmed(subject.substr(slash + 1))};
  for (int k = 0; k < 2; ++k) {
    const std::string& digits = parts[k];
    if (digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos) throw bad();
    const auto [end, error] = std::from_chars(digits.data(), digits.data() + digits.size(), index[k]);
    if (error == std::errc::result_out_of_range) index[k] = std::numeric_limits<long long>::max();
  }
  return std::make_pair(index[0], index[1]);
}

// Python's difflib.SequenceMatcher(None, a, b).ratio(): twice the characters of the
// recursively longest common blocks over both lengths (names are short: no junk rules).
int MatchingCharacters(const std::string& a, size_t alo, size_t ahi, const std::string& b, size_t blo, size_t bhi) {
  size_t best_i = alo, best_j = blo, best_k = 0;
  std::vector<size_t> previous(bhi - blo + 1, 0), current(bhi - blo + 1, 0);
  for (size_t i = alo; i < ahi; ++i) {
    for (size_t j = blo; j < bhi; ++j) {
      current[j - blo + 1] = a[i] == b[j] ? previous[j - blo] + 1 : 0;
      const size_t k = current[j - blo + 1];
      const size_t start_i = i + 1 - k, start_j = j + 1 - k;
      if (k > best_k || (k == best_k && k > 0 && (start_i < best_i || (start_i == best_i && start_j < best_j)))) {
        best_i = start_i, best_j = start_j, best_k = k;
      }
    }
    std::swap(previous, current);
  }
  if (best_k == 0) return 0;
  return static_cast<int>(best_k) + MatchingCharacters(a, alo, best_i, b, blo, best_j) +
         MatchingCharacters(a, best_i + best_k, ahi, b, best_j + best_k, bhi);
}

double Similarity(const std::string& a, const std::string& b) {
  if (a.empty() && b.empty()) return 1.0;
  return 2.0 * MatchingCharacters(a, 0, a.size(), b, 0, b.size()) / static_cast<double>(a.size() + b.size());
}

// The name most like `name` (difflib.get_close_matches(name, names, n=1)), or "".
std::string ClosestName(const std::string& name, const std::vector<std::string>& names) {
  constexpr double kCutoff = 0.6;
  std::string best;
  double best_score = -1.0;
  for (const auto& candidate : names) {
    const double score = Similarity(candidate, name);
    if (score < kCutoff) continue;
    if (score > best_score || (score == best_score && candidate > best)) best = candidate, best_score = score;
  }
  return best;
}

std::string Joined(const std::vector<std::string>& names) {
  std::string out;
  for (const auto& name : names) out += (out.empty() ? "" : ", ") + name;
  return out;
}

std::string Where(const ScaleMeasurement& measurement) {
  return "scale measurement " + PythonRepr(measurement.Label());
}

void CheckCameras(const ScaleMeasurement& measurement, const std::vector<std::string>& camera_names) {
  for (const auto& name : measurement.cameras) {
    if (std::find(camera_names.begin(), camera_names.end(), name) != camera_names.end()) continue;
    const std::string close = ClosestName(name, camera_names);
    throw std::invalid_argument(Where(measurement) + ": no camera " + PythonRepr(name) + " (cameras: " +
                                Joined(camera_names) + (close.empty() ? "" : "; did you mean " + close + "?") + ")");
  }
}

const ProjectedMarkers& RequireMarkers(const ScaleMeasurement& measurement, const ProjectedMarkers* markers) {
  if (markers == nullptr) {
    throw std::invalid_argument(Where(measurement) +
                                ": marker-size needs the projection sequence (sequence.json) for the marker "
                                "positions and size");
  }
  return *markers;
}

cv::Point2d MarkerPixel(const ScaleMeasurement& measurement, const ProjectedMarkers& markers) {
  if (!measurement.marker) {  // pixel centres on integers
    return {(markers.projector_width - 1) / 2.0, (markers.projector_height - 1) / 2.0};
  }
  const auto [array, marker] = *measurement.marker;
  if (array >= markers.arrays || marker >= markers.markers_per_array) {
    throw std::invalid_argument(Where(measurement) + ": no marker " + std::to_string(array) + "/" +
                                std::to_string(marker) + " in the sequence (" + std::to_string(markers.arrays) +
                                " arrays of " + std::to_string(markers.markers_per_array) +
                                " markers, indices from 0)");
  }
  return markers.centres[array * markers.markers_per_array + marker];
}

Eigen::Vector3d RegisteredCentre(const Calibration& calibration, const ScaleMeasurement& measurement,
                                 const std::string& name) {
  if (const CameraPose* pose = calibration.PoseOf(name)) return pose->Centre();
  const std::string reason = calibration.FailureOf(name);
  const std::string state = reason.empty() ? "is not in the calibration" : "failed to register (" + reason + ")";
  throw std::invalid_argument(Where(measurement) + ": camera " + PythonRepr(name) + " " + state);
}

double CameraHeight(const Calibration& calibration, const ScaleMeasurement& measurement) {
  const double height = RegisteredCentre(calibration, measurement, measurement.cameras[0]).z();
  if (!(height > 0)) {
    throw std::invalid_argument(Where(measurement) + ": camera " + PythonRepr(measurement.cameras[0]) +
                                " is not above the floor in the calibration (height " + FormatNumber("%.4g", height) + ")");
  }
  return height;
}

double CameraDistance(const Calibration& calibration, const ScaleMeasurement& measurement) {
  const Eigen::Vector3d a = RegisteredCentre(calibration, measurement, measurement.cameras[0]);
  const Eigen::Vector3d b = RegisteredCentre(calibration, measurement, measurement.cameras[1]);
  const double distance = (a - b).norm();
  if (!(distance > 0)) throw std::invalid_argument(Where(measurement) + ": the two cameras are at the same place");
  return distance;
}

// Mean side of the measured marker at scale 1 on the floor, through the least-squares
// homography from projector pixels to the floor of the reconstructed centres around it.
double MarkerSideOnFloor(const Calibration& calibration, const ScaleMeasurement& measurement,
                         const ProjectedMarkers& markers, double radius_sides, ScaleFit* fit) {
  if (!(radius_sides > 0)) {
    throw std::invalid_argument("marker neighbourhood radius must be positive, got " + PythonFloat(radius_sides) +
                                " sides");
  }
  const cv::Point2d centre = MarkerPixel(measurement, markers);
  const long long count = static_cast<long long>(markers.centres.size());
  const double radius = radius_sides * markers.marker_side_px;
  std::vector<cv::Point2d> pixels, floor;
  for (size_t p = 0; p < calibration.point_ids.size(); ++p) {
    const std::int64_t id = calibration.point_ids[p];
    if (id < 0 || id >= count) {
      throw std::invalid_argument(Where(measurement) + ": the calibration has point ids beyond the sequence's " +
                                  std::to_string(count) + " MSMs; is it the sequence of these tracks?");
    }
    if (cv::norm(markers.centres[id] - centre) > radius) continue;
    pixels.push_back(markers.centres[id]);
    floor.emplace_back(calibration.points(p, 0), calibration.points(p, 1));  // the floor is z = 0
  }
  if (static_cast<int>(pixels.size()) < kMinMarkerNeighbours) {
    throw std::invalid_argument(Where(measurement) + ": only " + std::to_string(pixels.size()) +
                                " reconstructed MSM centres within " + FormatNumber("%.0f", radius) +
                                " projector pixels of the marker measured (at " + FormatNumber("%.0f", centre.x) + ", " +
                                FormatNumber("%.0f", centre.y) + "); " + std::to_string(kMinMarkerNeighbours) +
                                " are needed: measure a marker that the cameras saw");
  }
  const cv::Mat H = cv::findHomography(pixels, floor, 0);
  if (H.empty()) throw std::invalid_argument(Where(measurement) + ": the MSM centres around the marker do not fit a plane");
  std::vector<cv::Point2d> mapped;
  cv::perspectiveTransform(pixels, mapped, H);
  double squares = 0.0;
  for (size_t p = 0; p < pixels.size(); ++p) squares += std::pow(cv::norm(mapped[p] - floor[p]), 2);
  fit->fitted_centres = static_cast<int>(pixels.size());
  fit->fit_rms = std::sqrt(squares / pixels.size());
  const double half = 0.5 * markers.marker_side_px;
  const std::vector<cv::Point2d> square = {centre + cv::Point2d(-half, -half), centre + cv::Point2d(half, -half),
                                           centre + cv::Point2d(half, half), centre + cv::Point2d(-half, half)};
  std::vector<cv::Point2d> corners;
  cv::perspectiveTransform(square, corners, H);
  double sides = 0.0;
  for (size_t k = 0; k < corners.size(); ++k) sides += cv::norm(corners[k] - corners[(k + 1) % corners.size()]);
  return sides / corners.size();
}

}  // namespace

std::string ScaleMeasurement::Label() const {
  return !text.empty() ? text : kind + "=" + FormatNumber("%g", metres) + " m";
}

void ScaleMeasurement::Check() const {
  const size_t cameras_needed = kind == "camera-height" ? 1 : kind == "distance" ? 2 : 0;
  if (FormOf(kind).empty()) throw std::invalid_argument("scale measurement: unknown kind " + PythonRepr(kind));
  if (!(std::isfinite(metres) && metres > 0)) {
    throw std::invalid_argument(Where(*this) + ": the length must be a positive number of metres");
  }
  if (cameras.size() != cameras_needed) {
    throw std::invalid_argument(Where(*this) + ": expected " + FormOf(kind));
  }
  if (marker && (kind != "marker-size" || marker->first < 0 || marker->second < 0)) {
    throw std::invalid_argument(Where(*this) + ": the marker must be ARRAY/MARKER (two indices from 0)");
  }
}

ProjectedMarkers ProjectedMarkers::FromSequence(const ingest::SequenceDescription& sequence) {
  ProjectedMarkers markers;
  markers.arrays = sequence.arrays;
  markers.markers_per_array = sequence.markers_per_array;
  markers.centres = sequence.centres;
  markers.marker_side_px = sequence.marker_px;
  markers.projector_width = sequence.projector_width;
  markers.projector_height = sequence.projector_height;
  markers.largest_side_px.assign(markers.centres.size(), std::numeric_limits<double>::quiet_NaN());
  for (size_t index = 0; index < sequence.patterns.size(); ++index) {
    const ingest::PatternSpec& pattern = sequence.patterns[index];
    for (const int marker : sequence.MarkersShown(static_cast<int>(index))) {
      double& side = markers.largest_side_px[static_cast<size_t>(pattern.array) * sequence.markers_per_array + marker];
      side = std::fmax(side, pattern.marker_side_px);
    }
  }
  markers.Check();
  return markers;
}

std::vector<double> ProjectedMarkers::LargestSidesOf(const std::vector<std::int64_t>& point_ids) const {
  std::vector<double> sides(point_ids.size(), std::numeric_limits<double>::quiet_NaN());
  for (size_t p = 0; p < point_ids.size(); ++p) {
    const std::int64_t id = point_ids[p];
    if (id >= 0 && id < static_cast<std::int64_t>(largest_side_px.size())) sides[p] = largest_side_px[id];
  }
  return sides;
}

ba::PixelMatrix ProjectedMarkers::PixelsOf(const std::vector<std::int64_t>& point_ids) const {
  ba::PixelMatrix pixels(static_cast<int>(point_ids.size()), 2);
  for (size_t p = 0; p < point_ids.size(); ++p) {
    const std::int64_t id = point_ids[p];
    if (id >= 0 && id < static_cast<std::int64_t>(centres.size())) {
      pixels.row(static_cast<int>(p)) << centres[id].x, centres[id].y;
    } else {
      pixels.row(static_cast<int>(p)).setConstant(std::numeric_limits<double>::quiet_NaN());
    }
  }
  return pixels;
}

void ProjectedMarkers::Check() const {
  if (arrays <= 0 || markers_per_array <= 0 || centres.size() != static_cast<size_t>(arrays) * markers_per_array) {
    throw std::invalid_argument("MSM centres must have shape (arrays, markers, 2), got " +
                                std::to_string(centres.size()) + " centres for " + std::to_string(arrays) +
                                " arrays of " + std::to_string(markers_per_array));
  }
  if (!(marker_side_px > 0)) {
    throw std::invalid_argument("marker side must be positive, got " + PythonFloat(marker_side_px) + " px");
  }
  if (!largest_side_px.empty() && largest_side_px.size() != centres.size()) {
    throw std::invalid_argument("largest marker sides: " + std::to_string(largest_side_px.size()) + " for " +
                                std::to_string(centres.size()) + " MSMs");
  }
  for (const double side : largest_side_px) {
    if (!std::isnan(side) && !(side > 0.0 && std::isfinite(side))) {
      throw std::invalid_argument("largest marker sides must be positive or NaN, got " + PythonFloat(side));
    }
  }
}

ScaleMeasurement ParseScale(const std::string& text) {
  const std::string where = "scale measurement " + PythonRepr(text);
  const std::string trimmed = Trimmed(text);
  const size_t colon = trimmed.find(':');
  if (colon == std::string::npos) throw std::invalid_argument(where + ": expected " + Syntax());
  ScaleMeasurement measurement;
  measurement.kind = trimmed.substr(0, colon);
  measurement.text = text;
  if (FormOf(measurement.kind).empty()) {
    throw std::invalid_argument(where + ": unknown kind " + PythonRepr(measurement.kind) +
                                " (expected camera-height, marker-size, distance)");
  }
  const std::string rest = trimmed.substr(colon + 1);
  const size_t equals = rest.rfind('=');
  if (equals == std::string::npos && measurement.kind != "marker-size") {
    throw std::invalid_argument(where + ": expected " + FormOf(measurement.kind));
  }
  const std::string subject = equals == std::string::npos ? "" : rest.substr(0, equals);
  measurement.metres = ParseMetres(where, equals == std::string::npos ? rest : rest.substr(equals + 1));
  if (measurement.kind == "marker-size") {
    if (equals != std::string::npos) measurement.marker = ParseMarker(where, subject);
  } else {
    measurement.cameras = ParseCameras(where, measurement.kind, subject);
  }
  return measurement;
}

void CheckMeasurement(const ScaleMeasurement& measurement, const std::vector<std::string>& camera_names,
                      const ProjectedMarkers* markers) {
  measurement.Check();
  if (markers) markers->Check();
  CheckCameras(measurement, camera_names);
  if (measurement.kind == "marker-size") MarkerPixel(measurement, RequireMarkers(measurement, markers));
}

ScaleFit ScaleFactor(const Calibration& calibration, const ScaleMeasurement& measurement,
                     const ProjectedMarkers* markers, double radius_sides) {
  calibration.Check();
  measurement.Check();
  if (markers) markers->Check();
  ScaleFit fit;
  if (measurement.kind == "camera-height") {
    fit.length = CameraHeight(calibration, measurement);
  } else if (measurement.kind == "distance") {
    fit.length = CameraDistance(calibration, measurement);
  } else {
    fit.length = MarkerSideOnFloor(calibration, measurement, RequireMarkers(measurement, markers), radius_sides, &fit);
  }
  fit.metres_per_unit = measurement.metres / fit.length;
  return fit;
}

}  // namespace calibproj::formats
