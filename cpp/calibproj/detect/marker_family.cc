#include "calibproj/detect/marker_family.h"

#include <apriltag/apriltag.h>
#include <apriltag/common/image_u8.h>

#include <opencv2/aruco.hpp>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <memory>
#include <stdexcept>
#include <utility>

#include "calibproj/detect/apriltag_family.h"

namespace calibproj::detect {

namespace {

using cv::aruco::PREDEFINED_DICTIONARY_NAME;

constexpr std::pair<const char*, PREDEFINED_DICTIONARY_NAME> kArucoDictionaries[] = {
    {"4X4_50", cv::aruco::DICT_4X4_50},
    {"4X4_100", cv::aruco::DICT_4X4_100},
    {"4X4_250", cv::aruco::DICT_4X4_250},
    {"4X4_1000", cv::aruco::DICT_4X4_1000},
    {"5X5_50", cv::aruco::DICT_5X5_50},
    {"5X5_100", cv::aruco::DICT_5X5_100},
    {"5X5_250", cv::aruco::DICT_5X5_250},
    {"5X5_1000", cv::aruco::DICT_5X5_1000},
    {"6X6_50", cv::aruco::DICT_6X6_50},
    {"6X6_100", cv::aruco::DICT_6X6_100},
    {"6X6_250", cv::aruco::DICT_6X6_250},
    {"6X6_1000", cv::aruco::DICT_6X6_1000},
    {"7X7_50", cv::aruco::DICT_7X7_50},
    {"7X7_100", cv::aruco::DICT_7X7_100},
    {"7X7_250", cv::aruco::DICT_7X7_250},
    {"7X7_1000", cv::aruco::DICT_7X7_1000},
    {"ARUCO_ORIGINAL", cv::aruco::DICT_ARUCO_ORIGINAL},
    {"APRILTAG_16h5", cv::aruco::DICT_APRILTAG_16h5},
    {"APRILTAG_25h9", cv::aruco::DICT_APRILTAG_25h9},
    {"APRILTAG_36h10", cv::aruco::DICT_APRILTAG_36h10},
    {"APRILTAG_36h11", cv::aruco::DICT_APRILTAG_36h11},
};

std::string Lower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return std::tolower(c); });
  return text;
}

std::string JoinSpecs(const std::string& system, const std::vector<std::string>& names) {
  std::string out;
  for (const auto& name : names) out += (out.empty() ? "" : ", ") + system + ":" + name;
  return out;
}

std::vector<std::string> ArucoNames() {
  std::vector<std::string> names;
  for (const auto& [name, unused] : kArucoDictionaries) names.emplace_back(name);
  return names;
}

// The canonical spelling of `name` among `choices`, compared case-insensitively.
std::string Canonical(const std::string& system, const std::string& name,
                      const std::vector<std::string>& choices) {
  for (const auto& choice : choices) {
    if (Lower(choice) == Lower(name)) return choice;
  }
  throw std::invalid_argument("unknown marker family '" + system + ":" + name + "' (choose from " +
                              JoinSpecs(system, choices) + ")");
}

PREDEFINED_DICTIONARY_NAME ArucoDictionaryId(const std::string& name) {
  for (const auto& [known, id] : kArucoDictionaries) {
    if (name == known) return id;
  }
  throw std::invalid_argument("unknown ArUco dictionary '" + name + "'");
}

cv::Ptr<cv::aruco::Dictionary> ArucoDictionaryNamed(const std::string& name) {
  return cv::aruco::getPredefinedDictionary(ArucoDictionaryId(name));
}

void CheckId(const MarkerFamily& family, int id) {
  const int count = MarkerIdCount(family);
  if (id < 0 || id >= count) {
    throw std::invalid_argument("marker id " + std::to_string(id) + " out of range for " + family.Spec() +
                                " (ids 0.." + std::to_string(count - 1) + ")");
  }
}

cv::Mat ArucoBits(const std::string& name, int id) {
  const auto dictionary = ArucoDictionaryNamed(name);
  const int n = dictionary->markerSize;
  // Rotation 0 of the codeword; the black border is one cell wide.
  const cv::Mat data = cv::aruco::Dictionary::getBitsFromByteList(dictionary->bytesList.row(id), n);
  cv::Mat bits = cv::Mat::zeros(n + 2, n + 2, CV_8U);
  data.copyTo(bits(cv::Rect(1, 1, n, n)));
  return bits;
}

// Classic families (reversed_border false) draw a white quiet ring around the black
// border; that ring is the background, not the marker.
int AprilTagQuietRing(const apriltag_family_t& family) {
  return family.reversed_border ? 0 : (family.total_width - family.width_at_border) / 2;
}

// Frees an image from apriltag_to_image(). Debian's libapriltag does not export
// image_u8_destroy(), which is free(buf) then free(image) (both calloc'ed).
struct AprilTagImageDeleter {
  void operator()(image_u8_t* image) const {
    std::free(image->buf);
    std::free(image);
  }
};

cv::Mat AprilTagBits(const std::string& name, int id) {
  const auto family = CreateAprilTagFamily(name);
  const std::unique_ptr<image_u8_t, AprilTagImageDeleter> image(apriltag_to_image(family.get(), id));
  if (!image) throw std::runtime_error("libapriltag could not render " + name + " id " + std::to_string(id));
  const int ring = AprilTagQuietRing(*family);
  const int side = family->total_width - 2 * ring;
  // Turned by 180 degrees: that is how OpenCV draws the same tags (DICT_APRILTAG_*),
  // so corner 0 of both detectors is the top-left corner of this grid.
  cv::Mat bits(side, side, CV_8U);
  for (int row = 0; row < side; ++row) {
    for (int col = 0; col < side; ++col) {
      const uint8_t value = image->buf[(row + ring) * image->stride + col + ring];
      bits.at<uint8_t>(side - 1 - row, side - 1 - col) = value > 127 ? 1 : 0;
    }
  }
  return bits;
}

}  // namespace

std::string MarkerFamily::SystemName() const { return system == MarkerSystemKind::kAruco ? "aruco" : "apriltag"; }

std::string MarkerFamily::Spec() const { return SystemName() + ":" + name; }

MarkerFamily ParseMarkerFamily(const std::string& spec) {
  const auto colon = spec.find(':');
  const std::string system = Lower(spec.substr(0, colon));
  const std::string name = colon == std::string::npos ? "" : spec.substr(colon + 1);
  if (system == "aruco") return {MarkerSystemKind::kAruco, Canonical("aruco", name, ArucoNames())};
  if (system == "apriltag") return {MarkerSystemKind::kAprilTag, Canonical("apriltag", name, AprilTagFamilyNames())};
  throw std::invalid_argument("unknown marker family '" + spec +
                              "': expected 'aruco:<dictionary>' or 'apriltag:<family>' (choose from " +
                              JoinSpecs("aruco", ArucoNames()) + ", " +
                              JoinSpecs("apriltag", AprilTagFamilyNames()) + ")");
}

std::vector<std::string> MarkerFamilySpecs() {
  std::vector<std::string> specs;
  for (const auto& name : ArucoNames()) specs.push_back("aruco:" + name);
  for (const auto& name : AprilTagFamilyNames()) specs.push_back("apriltag:" + name);
  return specs;
}

int MarkerIdCount(const MarkerFamily& family) {
  if (family.system == MarkerSystemKind::kAruco) return ArucoDictionaryNamed(family.name)->bytesList.rows;
  return static_cast<int>(CreateAprilTagFamily(family.name)->ncodes);
}

MarkerGeometry GetMarkerGeometry(const MarkerFamily& family) {
  if (family.system == MarkerSystemKind::kAruco) {
    const int side = ArucoDictionaryNamed(family.name)->markerSize + 2;
    return {side, side};
  }
  const auto tag = CreateAprilTagFamily(family.name);
  return {tag->total_width - 2 * AprilTagQuietRing(*tag), tag->width_at_border};
}

cv::Mat MarkerBits(const MarkerFamily& family, int id) {
  CheckId(family, id);
  return family.system == MarkerSystemKind::kAruco ? ArucoBits(family.name, id) : AprilTagBits(family.name, id);
}

cv::Ptr<cv::aruco::Dictionary> ArucoDictionary(const MarkerFamily& family) {
  if (family.system != MarkerSystemKind::kAruco) {
    throw std::invalid_argument(family.Spec() + " is not an ArUco dictionary");
  }
  return ArucoDictionaryNamed(family.name);
}

MarkerFamilyInfo DescribeMarkerFamily(const std::string& spec) {
  const MarkerFamily family = ParseMarkerFamily(spec);
  return {family.Spec(), family.SystemName(), family.name, MarkerIdCount(family), GetMarkerGeometry(family)};
}

}  // namespace calibproj::detect
