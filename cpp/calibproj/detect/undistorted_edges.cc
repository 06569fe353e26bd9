#include "calibproj/detect/undistorted_edges.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace calibproj::detect {

namespace {

// Samples along one profile at most (the bound of UndistortedEdgeOptions).
constexpr int kMaxProfileSamples = 256;

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument("undistorted edge options: " + message);
}

// A profile across an edge: its base point and outward unit normal in the image, and
// where they are in undistorted pixels: a point t image pixels out along the profile is
// undistorted_base + t * undistorted_per_px, to first order in t. The profiles of a pass
// are based on the edge the previous pass found, so that at the fixed point t is only
// the edge points' scatter (~0.05 px), and the neglected term (the distortion's curvature
// times t^2) a few 1e-6 px.
struct Profile {
  cv::Point2d base;
  cv::Point2d normal;
  cv::Point2d undistorted_base;
  cv::Point2d undistorted_per_px;
};

struct EdgePoint {
  cv::Point2d undistorted;  // undistorted pixels
  double contrast;          // outer minus inner level
};

// 32.32 fixed point of v, rounded (std::llround is a library call).
std::int64_t Fixed(double v) {
  constexpr double kOne = 4294967296.0;  // 2^32
  return static_cast<std::int64_t>(v * kOne + (v >= 0.0 ? 0.5 : -0.5));
}

// How far a profile reaches inside the marker and outside it, image pixels.
struct Reach {
  double inward;
  double outward;
};

// Where the edge crosses a profile, from the area under the normalised profile: for a
// blurred step from level a (inside, at -r_in) to b (outside, at +r_out), the integral
// of (I - a) / (b - a) over [-r_in, r_out] is r_out - s, s the edge's position.
std::optional<EdgePoint> LocateEdge(const cv::Mat& gray, const cv::Point2d& origin, const Profile& profile,
                                    const Reach& reach, const UndistortedEdgeOptions& options) {
  const double length = reach.inward + reach.outward;
  const int steps = std::clamp(static_cast<int>(std::ceil(length * options.profile_samples_per_px)), 4,
                               std::max(4, options.max_profile_samples));
  const double step = length / steps;
  // The profile is a straight segment: inside the crop at both ends, inside throughout.
  const cv::Point2d first = profile.base - profile.normal * reach.inward - origin;
  const cv::Point2d last = profile.base + profile.normal * reach.outward - origin;
  const auto inside = [&gray](const cv::Point2d& p) {
    return p.x >= 0.0 && p.y >= 0.0 && p.x <= gray.cols - 1.0 && p.y <= gray.rows - 1.0;
  };
  if (!inside(first) || !inside(last)) return std::nullopt;
  // Bilinear samples along it, stepped in 32.32 fixed point (exact to 1e-8 px over a
  // profile): the refinement's innermost loop, where converting floating-point positions
  // cost most of the time.
  std::array<float, kMaxProfileSamples + 1> levels;
  const cv::Point2d delta = profile.normal * step;
  const std::int64_t step_x = Fixed(delta.x), step_y = Fixed(delta.y);
  std::int64_t x = Fixed(first.x), y = Fixed(first.y);
  const int last_column = gray.cols - 2, last_row = gray.rows - 2;
  const std::size_t stride = gray.step[0];
  for (int i = 0; i <= steps; ++i, x += step_x, y += step_y) {
    // Rounding may carry the far end a hair past the last pixel: held at the border.
    const int x0 = std::clamp(static_cast<int>(x >> 32), 0, last_column);
    const int y0 = std::clamp(static_cast<int>(y >> 32), 0, last_row);
    const float fx = static_cast<float>(x - (static_cast<std::int64_t>(x0) << 32)) * (1.0f / 4294967296.0f);
    const float fy = static_cast<float>(y - (static_cast<std::int64_t>(y0) << 32)) * (1.0f / 4294967296.0f);
    const uchar* top = gray.data + static_cast<std::size_t>(y0) * stride + x0;
    const uchar* bottom = top + stride;
    const float upper = top[0] + fx * (top[1] - top[0]);
    const float lower = bottom[0] + fx * (bottom[1] - bottom[0]);
    levels[i] = upper + fy * (lower - upper);
  }
  const float inner = levels[0], contrast = levels[steps] - inner;
  if (std::abs(contrast) < 1.0f) return std::nullopt;
  // Trapezoids of the normalised profile, 0 at its first sample and 1 at its last.
  const float scale = 1.0f / contrast;
  float sum = 0.5f;
  for (int i = 1; i < steps; ++i) sum += std::clamp((levels[i] - inner) * scale, 0.0f, 1.0f);
  const double area = sum * step;
  return EdgePoint{profile.undistorted_base + profile.undistorted_per_px * (reach.outward - area), contrast};
}

// Profiles along the undistorted segment from `from` to `to`, mapped into the image.
std::vector<Profile> EdgeProfiles(const LensTables& lens, const cv::Point2d& from, const cv::Point2d& to,
                                  double outward, const UndistortedEdgeOptions& options) {
  const double length = cv::norm(to - from);
  const cv::Point2d along = (to - from) / length;
  // Image y points down: (y, -x) is outward for corners in clockwise order.
  const cv::Point2d normal = cv::Point2d(along.y, -along.x) * outward;
  const double usable = length * (1.0 - 2.0 * options.end_margin);
  const int count = std::clamp(static_cast<int>(usable / options.spacing_px), options.min_samples,
                               std::max(options.min_samples, options.max_samples));
  std::vector<cv::Point2d> undistorted;
  for (int i = 0; i < count; ++i) {
    const cv::Point2d base = from + along * (length * options.end_margin + usable * (i + 0.5) / count);
    undistorted.push_back(base);
    undistorted.push_back(base + normal);  // fixes the normal's direction in the image
  }
  const std::vector<cv::Point2d> image = lens.Distort(undistorted);
  std::vector<Profile> profiles;
  for (int i = 0; i < count; ++i) {
    const cv::Point2d direction = image[2 * i + 1] - image[2 * i];
    const double length_px = cv::norm(direction);  // image pixels per undistorted pixel of normal
    profiles.push_back({image[2 * i], direction / length_px, undistorted[2 * i], normal / length_px});
  }
  return profiles;
}

// Line a x + b y + c = 0 through the undistorted edge points that cross the border with
// the edge's polarity and enough contrast.
std::optional<cv::Vec3d> FitLine(const std::vector<EdgePoint>& found, const UndistortedEdgeOptions& options) {
  if (found.empty()) return std::nullopt;
  std::vector<double> contrasts;
  for (const auto& p : found) contrasts.push_back(p.contrast);
  std::nth_element(contrasts.begin(), contrasts.begin() + contrasts.size() / 2, contrasts.end());
  const double median = contrasts[contrasts.size() / 2];
  std::vector<cv::Point2d> undistorted;
  for (const auto& p : found) {
    if (p.contrast * median > 0 && std::abs(p.contrast) >= options.min_contrast * std::abs(median)) {
      undistorted.push_back(p.undistorted);
    }
  }
  if (static_cast<int>(undistorted.size()) < std::max(2, options.min_samples / 2)) return std::nullopt;
  cv::Vec4d line;  // direction (vx, vy) and a point (x0, y0)
  cv::fitLine(undistorted, line, cv::DIST_L2, 0, 1e-4, 1e-4);
  return cv::Vec3d(-line[1], line[0], line[1] * line[2] - line[0] * line[3]);
}

double MeanSide(const Quad& quad) {
  double total = 0.0;
  for (int k = 0; k < 4; ++k) total += cv::norm(quad[(k + 1) % 4] - quad[k]);
  return 0.25 * total;
}

// One pass: lines through the edges near `quad` (undistorted), their intersections.
std::optional<Quad> RefinePass(const cv::Mat& gray, const cv::Point2d& origin, const LensTables& lens, int cells,
                               const Quad& quad, double image_module, const UndistortedEdgeOptions& options) {
  double signed_area = 0.0;
  for (int k = 0; k < 4; ++k) signed_area += quad[k].cross(quad[(k + 1) % 4]);
  const double outward = signed_area > 0 ? 1.0 : -1.0;
  const Reach reach{options.search_fraction * image_module, options.outward_fraction * image_module};
  cv::Vec3d lines[4];
  for (int k = 0; k < 4; ++k) {
    std::vector<EdgePoint> found;
    for (const Profile& profile : EdgeProfiles(lens, quad[k], quad[(k + 1) % 4], outward, options)) {
      if (auto point = LocateEdge(gray, origin, profile, reach, options)) {
        found.push_back(*point);
      }
    }
    const auto line = FitLine(found, options);
    if (!line) return std::nullopt;
    lines[k] = *line;
  }
  const double module = MeanSide(quad) / cells;
  Quad refined;
  for (int k = 0; k < 4; ++k) {
    // Corner k joins edge k - 1 (into it) and edge k (out of it).
    const cv::Vec3d point = lines[(k + 3) % 4].cross(lines[k]);
    if (std::abs(point[2]) < 1e-12) return std::nullopt;
    refined[k] = cv::Point2d(point[0] / point[2], point[1] / point[2]);
    if (!(cv::norm(refined[k] - quad[k]) <= 0.5 * module)) return std::nullopt;
  }
  return refined;
}

}  // namespace

void UndistortedEdgeOptions::Check() const {
  Require(search_fraction > 0.0 && search_fraction <= 1.0, "search_fraction must be in (0, 1]");
  Require(outward_fraction > 0.0 && outward_fraction <= 1.0, "outward_fraction must be in (0, 1]");
  Require(spacing_px >= 0.01 && std::isfinite(spacing_px), "spacing_px must be at least 0.01");
  Require(min_samples >= 2, "min_samples must be at least 2");
  Require(max_samples >= min_samples && max_samples <= 10'000, "max_samples must be in [min_samples, 10000]");
  Require(max_profile_samples >= 4 && max_profile_samples <= kMaxProfileSamples,
          "max_profile_samples must be in [4, " + std::to_string(kMaxProfileSamples) + "]");
  Require(profile_samples_per_px >= 1.0 && std::isfinite(profile_samples_per_px),
          "profile_samples_per_px must be at least 1");
  Require(end_margin >= 0.0 && end_margin < 0.5, "end_margin must be in [0, 0.5)");
  Require(min_contrast >= 0.0 && min_contrast <= 1.0, "min_contrast must be in [0, 1]");
  Require(passes >= 1 && passes <= 100, "passes must be in [1, 100]");
  Require(tolerance_px >= 0.0 && std::isfinite(tolerance_px), "tolerance_px must be non-negative");
}

std::optional<Quad> RefineUndistortedCorners(const cv::Mat& gray, const cv::Point& origin, const LensTables& lens,
                                             int cells, const Quad& distorted, const UndistortedEdgeOptions& options) {
  if (options.passes > 100) throw std::invalid_argument("edge refinement: passes must be at most 100");
  if (cells < 1 || cells > 1000) throw std::invalid_argument("edge refinement: cells must be in [1, 1000]");
  for (const cv::Point2d& corner : distorted) {
    if (!std::isfinite(corner.x) || !std::isfinite(corner.y)) {
      throw std::invalid_argument("edge refinement: non-finite corner");
    }
  }
  if (gray.empty() || gray.type() != CV_8UC1) {
    throw std::invalid_argument("edge refinement: expected a non-empty 8-bit image");
  }
  const std::vector<cv::Point2d> corners = lens.Undistort({distorted.begin(), distorted.end()});
  std::optional<Quad> quad = Quad{corners[0], corners[1], corners[2], corners[3]};
  // Profiles are measured in image pixels: their length follows the detected module.
  const double image_module = MeanSide(distorted) / cells;
  // The moves shrink geometrically: once the next is predicted below tolerance_px, it
  // is not made.
  double previous = 0.0;
  for (int pass = 0; pass < options.passes; ++pass) {
    const std::optional<Quad> next =
        RefinePass(gray, cv::Point2d(origin.x, origin.y), lens, cells, *quad, image_module, options);
    if (!next) return std::nullopt;
    double moved = 0.0;
    for (int k = 0; k < 4; ++k) moved = std::max(moved, cv::norm((*next)[k] - (*quad)[k]));
    quad = next;
    const bool next_below_tolerance =
        pass > 0 && moved < 0.5 * previous && moved * (moved / previous) <= options.tolerance_px;
    if (moved <= options.tolerance_px || next_below_tolerance) break;
    previous = moved;
  }
  return quad;
}

}  // namespace calibproj::detect
