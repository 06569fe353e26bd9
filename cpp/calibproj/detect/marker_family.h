#pragma once
// Marker families named by spec strings:
//   "aruco:<DICT>"       an OpenCV 4.6 predefined dictionary, e.g. "aruco:4X4_50",
//                        "aruco:ARUCO_ORIGINAL", "aruco:APRILTAG_36h11";
//   "apriltag:<family>"  a libapriltag family, e.g. "apriltag:tag36h11",
//                        "apriltag:tagStandard41h12".
// The system and the name are matched case-insensitively; Spec() is canonical.

#include <opencv2/aruco/dictionary.hpp>
#include <opencv2/core.hpp>

#include <string>
#include <vector>

namespace calibproj::detect {

enum class MarkerSystemKind { kAruco, kAprilTag };

struct MarkerFamily {
  MarkerSystemKind system = MarkerSystemKind::kAruco;
  std::string name;  // canonical name without the system, e.g. "4X4_50" or "tag36h11"

  std::string SystemName() const;  // "aruco" or "apriltag"
  std::string Spec() const;        // "aruco:4X4_50"
};

// Parses a spec string. Throws std::invalid_argument naming the unknown system or
// family and listing the valid choices.
MarkerFamily ParseMarkerFamily(const std::string& spec);

// Every spec this build accepts: the ArUco dictionaries, then the AprilTag families.
std::vector<std::string> MarkerFamilySpecs();

// Number of distinct marker ids; valid ids are 0 .. count - 1.
int MarkerIdCount(const MarkerFamily& family);

// Cell layout of a marker, in modules (cells). Both squares share the marker centre.
struct MarkerGeometry {
  // Side of the drawn pattern, i.e. of MarkerBits(). ArUco: bits + 2 (black border).
  // AprilTag: libapriltag's rendering without the white quiet ring that classic
  // families (tag36h11, ...) put around their black border; families with the
  // border inside (tagStandard41h12, ...) keep their outer data ring.
  int grid_cells = 0;
  // Side of the square whose corners the detectors return (the outer edge of the
  // black border for ArUco and classic AprilTags, libapriltag's width_at_border
  // for the others).
  int quad_cells = 0;
};

MarkerGeometry GetMarkerGeometry(const MarkerFamily& family);

// What a family is made of, as one record.
struct MarkerFamilyInfo {
  std::string spec;    // canonical, e.g. "aruco:4X4_50"
  std::string system;  // "aruco" or "apriltag"
  std::string name;    // without the system
  int id_count = 0;
  MarkerGeometry geometry;
};

// Throws std::invalid_argument as ParseMarkerFamily does.
MarkerFamilyInfo DescribeMarkerFamily(const std::string& spec);

// Marker `id` as a grid_cells x grid_cells CV_8U matrix of 0 (black) and 1 (white)
// cells, row 0 at the top, as printed black on white: exactly what the detectors
// expect. Both detectors return corner 0 at the top-left corner of this grid (AprilTag
// grids are libapriltag's rendering turned by 180 degrees, as OpenCV draws its
// DICT_APRILTAG_* copies of the same tags). Throws std::invalid_argument for an id
// out of range.
cv::Mat MarkerBits(const MarkerFamily& family, int id);

// OpenCV's dictionary of an ArUco family; throws std::invalid_argument for AprilTag.
cv::Ptr<cv::aruco::Dictionary> ArucoDictionary(const MarkerFamily& family);

}  // namespace calibproj::detect
