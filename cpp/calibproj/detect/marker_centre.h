#pragma once
// Centre of a detected square marker: the intersection of its diagonals.
// A homography maps the diagonals of a square onto the diagonals of its image, so
// this point is the image of the marker's centre under any perspective view
// (in undistorted pixel coordinates).

#include <vector>

#include "calibproj/detect/detections.h"

namespace calibproj::detect {

// Intersection of the lines corners[0]-corners[2] and corners[1]-corners[3]; NaN
// coordinates for a degenerate quad whose diagonals are parallel.
cv::Point2d DiagonalIntersection(const Quad& corners);

std::vector<cv::Point2d> MarkerCentres(const std::vector<Quad>& corners);

}  // namespace calibproj::detect
