#pragma once
// Metric scale of a calibration from one length measured in the room
// (`--scale` of both command lines; the Python module calibproj.scale.metric documents the
// measurements and how a marker's size becomes a scale).
//
// Errors are std::invalid_argument with the message shown to the user.

#include <opencv2/core.hpp>

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "calibproj/ba/bundle_adjuster.h"
#include "calibproj/formats/calibration.h"
#include "calibproj/ingest/sequence_description.h"

namespace calibproj::formats {

struct ScaleMeasurement {
  std::string kind;                         // camera-height, distance or marker-size
  double metres = 0.0;                      // the measured length
  std::vector<std::string> cameras;         // one (camera-height) or two (distance)
  std::optional<std::pair<long long, long long>> marker;  // (array, marker); none: nearest the centre
  std::string text;                         // as written, for messages

  // The text, or "KIND=METRES m" for a measurement built in code.
  std::string Label() const;
  // std::invalid_argument unless kind, length, cameras and marker fit together.
  void Check() const;
};

// Where the projector draws the MSMs: MSM (array, marker) has point id
// array * markers_per_array + marker and its centre at centres[that id].
struct ProjectedMarkers {
  int arrays = 0;
  int markers_per_array = 0;
  std::vector<cv::Point2d> centres;  // projector pixels
  double marker_side_px = 0.0;       // side at scale 1, border included
  int projector_width = 0, projector_height = 0;
  // Per MSM the side of the largest marker the sequence draws at its centre (projector
  // pixels), NaN where it draws none; empty when not known.
  std::vector<double> largest_side_px;

  static ProjectedMarkers FromSequence(const ingest::SequenceDescription& sequence);
  // std::invalid_argument when the shapes or the side make no sense.
  void Check() const;
  // Per point id its projector pixel; NaN for an id beyond the sequence's MSMs.
  ba::PixelMatrix PixelsOf(const std::vector<std::int64_t>& point_ids) const;
  // Per point id its largest marker's side; NaN where not known.
  std::vector<double> LargestSidesOf(const std::vector<std::int64_t>& point_ids) const;
};

// Neighbourhood fitted around the measured marker, in marker sides (projector pixels).
constexpr double kDefaultMarkerRadiusSides = 6.0;
// A homography has 8 degrees of freedom; twice as many centres keep the fit stable.
constexpr int kMinMarkerNeighbours = 16;

ScaleMeasurement ParseScale(const std::string& text);

// What can be checked before calibrating: the cameras exist (a mistyped name gets the
// closest one as a hint), the marker is in the sequence.
void CheckMeasurement(const ScaleMeasurement& measurement, const std::vector<std::string>& camera_names,
                      const ProjectedMarkers* markers);

struct ScaleFit {
  double metres_per_unit = 0.0;
  double length = 0.0;        // the measured length in calibration units
  int fitted_centres = 0;     // marker-size: MSM centres of the floor homography
  double fit_rms = 0.0;       // marker-size: their RMS distance to it, calibration units
};

ScaleFit ScaleFactor(const Calibration& calibration, const ScaleMeasurement& measurement,
                     const ProjectedMarkers* markers, double radius_sides = kDefaultMarkerRadiusSides);

}  // namespace calibproj::formats
