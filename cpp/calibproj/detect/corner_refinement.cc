#include "calibproj/detect/corner_refinement.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace calibproj::detect {

namespace {

// Far above the defaults; past them a bad option makes refinement loop for ages.
constexpr int kMaxWindowPx = 1000;
constexpr int kMaxIterations = 10'000;
constexpr double kMinEdgeSpacingPx = 0.01;
constexpr int kMaxEdgeSamples = 10'000;
constexpr int kMaxEdgePasses = 100;

// Step between samples of one intensity profile, in pixels.
constexpr double kProfileStepPx = 0.1;

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument("corner refinement options: " + message);
}

double MeanSide(const Quad& corners) {
  double sum = 0.0;
  for (int k = 0; k < 4; ++k) sum += cv::norm(corners[(k + 1) % 4] - corners[k]);
  return sum / 4.0;
}

void RefineWithCornerSubPix(const cv::Mat& gray, const CornerRefinementOptions& options, Quad* corners) {
  const double half_window = std::clamp(options.window_fraction * MeanSide(*corners), double(options.window_min_px),
                                        double(options.window_max_px));
  const int window = static_cast<int>(std::lround(half_window));
  std::vector<cv::Point2f> points(corners->begin(), corners->end());
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, options.max_iterations,
                                  options.epsilon_px);
  cv::cornerSubPix(gray, points, cv::Size(window, window), cv::Size(-1, -1), criteria);
  for (int k = 0; k < 4; ++k) (*corners)[k] = cv::Point2d(points[k].x, points[k].y);
}

// Bilinear intensity at a sub-pixel position (OpenCV pixel convention), edges replicated.
double Intensity(const cv::Mat& gray, const cv::Point2d& p) {
  const double x = std::clamp(p.x, 0.0, gray.cols - 1.0);
  const double y = std::clamp(p.y, 0.0, gray.rows - 1.0);
  const int x0 = std::min(static_cast<int>(x), gray.cols - 2);
  const int y0 = std::min(static_cast<int>(y), gray.rows - 2);
  const double fx = x - x0, fy = y - y0;
  const uint8_t* row0 = gray.ptr<uint8_t>(y0);
  const uint8_t* row1 = gray.ptr<uint8_t>(y0 + 1);
  return (1 - fy) * ((1 - fx) * row0[x0] + fx * row0[x0 + 1]) + fy * ((1 - fx) * row1[x0] + fx * row1[x0 + 1]);
}

struct EdgeSample {
  cv::Point2d point;  // where the edge crosses the profile
  double contrast;    // outer minus inner level (signed)
};

// Where the edge crosses the profile through `base` along the outward `normal`, by the
// area of the normalised profile: for a step between levels a (at -r) and b (at +r)
// blurred by any symmetric kernel, the integral of (I - a) / (b - a) over [-r, r] is
// r - s_edge.
std::optional<EdgeSample> LocateEdge(const cv::Mat& gray, const cv::Point2d& base, const cv::Point2d& normal,
                                     double half_range) {
  const int steps = std::max(2, static_cast<int>(std::ceil(2.0 * half_range / kProfileStepPx)));
  const double step = 2.0 * half_range / steps;
  std::vector<double> profile(steps + 1);
  for (int i = 0; i <= steps; ++i) profile[i] = Intensity(gray, base + normal * (-half_range + i * step));
  const double inner = profile.front(), outer = profile.back();
  const double contrast = outer - inner;
  if (std::abs(contrast) < 1.0) return std::nullopt;
  double area = 0.0;
  for (int i = 0; i < steps; ++i) {
    const double a = (profile[i] - inner) / contrast, b = (profile[i + 1] - inner) / contrast;
    area += 0.5 * (std::clamp(a, 0.0, 1.0) + std::clamp(b, 0.0, 1.0)) * step;
  }
  return EdgeSample{base + normal * (half_range - area), contrast};
}

// Line (a, b, c), a x + b y + c = 0, through the samples that cross the border with
// the edge's polarity and enough contrast.
std::optional<cv::Vec3d> FitEdgeLine(const std::vector<EdgeSample>& samples, const CornerRefinementOptions& options) {
  std::vector<double> contrasts;
  for (const auto& sample : samples) contrasts.push_back(sample.contrast);
  std::nth_element(contrasts.begin(), contrasts.begin() + contrasts.size() / 2, contrasts.end());
  const double median = contrasts[contrasts.size() / 2];
  std::vector<cv::Point2f> points;
  for (const auto& sample : samples) {
    if (sample.contrast * median > 0 && std::abs(sample.contrast) >= options.edge_min_contrast * std::abs(median)) {
      points.emplace_back(sample.point);
    }
  }
  if (static_cast<int>(points.size()) < std::max(2, options.edge_min_samples / 2)) return std::nullopt;
  cv::Vec4f line;  // direction (vx, vy) and a point (x0, y0)
  cv::fitLine(points, line, cv::DIST_L2, 0, 0.01, 0.01);
  return cv::Vec3d(-line[1], line[0], line[1] * line[2] - line[0] * line[3]);
}

std::optional<cv::Vec3d> EdgeLine(const cv::Mat& gray, const cv::Point2d& from, const cv::Point2d& to,
                                  double outward, double half_range, const CornerRefinementOptions& options) {
  const double length = cv::norm(to - from);
  const cv::Point2d along = (to - from) / length;
  // Image y points down, so (y, -x) is outward for corners in clockwise order.
  const cv::Point2d normal = cv::Point2d(along.y, -along.x) * outward;
  const double usable = length * (1.0 - 2.0 * options.edge_end_margin);
  const int count = std::max(options.edge_min_samples, static_cast<int>(usable / options.edge_spacing_px));
  std::vector<EdgeSample> samples;
  for (int i = 0; i < count; ++i) {
    const double t = length * options.edge_end_margin + usable * (i + 0.5) / count;
    if (auto sample = LocateEdge(gray, from + along * t, normal, half_range)) samples.push_back(*sample);
  }
  if (samples.empty()) return std::nullopt;
  return FitEdgeLine(samples, options);
}

bool RefineWithEdgeLines(const cv::Mat& gray, int cells, const CornerRefinementOptions& options, Quad* corners) {
  const Quad& quad = *corners;
  double signed_area = 0.0;
  for (int k = 0; k < 4; ++k) signed_area += quad[k].cross(quad[(k + 1) % 4]);
  const double outward = signed_area > 0 ? 1.0 : -1.0;
  const double module = MeanSide(quad) / cells;
  const double half_range = options.edge_search_fraction * module;

  cv::Vec3d lines[4];
  for (int k = 0; k < 4; ++k) {
    const auto line = EdgeLine(gray, quad[k], quad[(k + 1) % 4], outward, half_range, options);
    if (!line) return false;
    lines[k] = *line;
  }
  Quad refined;
  for (int k = 0; k < 4; ++k) {
    // Corner k joins edge k - 1 (into it) and edge k (out of it).
    const cv::Vec3d point = lines[(k + 3) % 4].cross(lines[k]);
    if (std::abs(point[2]) < 1e-12) return false;
    refined[k] = cv::Point2d(point[0] / point[2], point[1] / point[2]);
    if (!(cv::norm(refined[k] - quad[k]) <= 0.5 * module)) return false;
  }
  *corners = refined;
  return true;
}

}  // namespace

void CornerRefinementOptions::Check() const {
  Require(window_fraction > 0.0 && std::isfinite(window_fraction), "window_fraction must be positive");
  Require(window_min_px >= 1, "window_min_px must be at least 1");
  Require(window_max_px >= window_min_px, "window_max_px must be at least window_min_px");
  Require(window_max_px <= kMaxWindowPx, "window_max_px must be at most " + std::to_string(kMaxWindowPx));
  Require(max_iterations > 0 && max_iterations <= kMaxIterations,
          "max_iterations must be in [1, " + std::to_string(kMaxIterations) + "]");
  Require(epsilon_px > 0.0 && std::isfinite(epsilon_px), "epsilon_px must be positive");
  Require(edge_search_fraction > 0.0 && edge_search_fraction <= 1.0, "edge_search_fraction must be in (0, 1]");
  Require(edge_spacing_px >= kMinEdgeSpacingPx && std::isfinite(edge_spacing_px),
          "edge_spacing_px must be at least " + std::to_string(kMinEdgeSpacingPx));
  Require(edge_min_samples >= 2 && edge_min_samples <= kMaxEdgeSamples,
          "edge_min_samples must be in [2, " + std::to_string(kMaxEdgeSamples) + "]");
  Require(edge_end_margin >= 0.0 && edge_end_margin < 0.5, "edge_end_margin must be in [0, 0.5)");
  Require(edge_min_contrast >= 0.0 && edge_min_contrast <= 1.0, "edge_min_contrast must be in [0, 1]");
  Require(edge_passes >= 1 && edge_passes <= kMaxEdgePasses,
          "edge_passes must be in [1, " + std::to_string(kMaxEdgePasses) + "]");
}

void RefineCorners(const cv::Mat& gray, int cells, const CornerRefinementOptions& options, Quad* corners) {
  if (options.method == CornerRefinement::kNone) return;
  if (options.method == CornerRefinement::kSubpix) {
    RefineWithCornerSubPix(gray, options, corners);
    return;
  }
  for (int pass = 0; pass < options.edge_passes; ++pass) {
    if (!RefineWithEdgeLines(gray, cells, options, corners)) return;
  }
}

}  // namespace calibproj::detect
