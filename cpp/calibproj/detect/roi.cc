#include "calibproj/detect/roi.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>
#include <string>

#include "calibproj/detect/marker_centre.h"

namespace calibproj::detect {

namespace {

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument("ROI options: " + message);
}

int AlignDown(int value, int alignment) {
  return static_cast<int>(std::floor(static_cast<double>(value) / alignment)) * alignment;
}

// Points along the edges of the square of side `side` centred on `centre`, mapped to
// distorted image pixels with the homography of the surface the centre lands on; the
// first four are the corners (top-left, top-right, bottom-right, bottom-left).
std::vector<cv::Point2d> SquareOutline(const ProjectorHomography& homography, const CameraIntrinsics& lens,
                                       const cv::Point2d& centre, double side, int edge_points) {
  const cv::Matx33d& H = homography.SurfaceAt(centre);
  const double h = 0.5 * side;
  const cv::Point2d corners[4] = {centre + cv::Point2d(-h, -h), centre + cv::Point2d(h, -h),
                                  centre + cv::Point2d(h, h), centre + cv::Point2d(-h, h)};
  std::vector<cv::Point2d> undistorted;
  for (const auto& corner : corners) undistorted.push_back(ApplyHomography(H, corner));
  for (int edge = 0; edge < 4; ++edge) {
    for (int k = 1; k < edge_points; ++k) {
      const double s = static_cast<double>(k) / edge_points;
      undistorted.push_back(ApplyHomography(H, corners[edge] * (1.0 - s) + corners[(edge + 1) % 4] * s));
    }
  }
  return DistortPixels(lens, undistorted);
}

cv::Rect2d BoundingBox(const std::vector<cv::Point2d>& points) {
  double x0 = points[0].x, y0 = points[0].y, x1 = x0, y1 = y0;
  for (const auto& p : points) {
    x0 = std::min(x0, p.x);
    y0 = std::min(y0, p.y);
    x1 = std::max(x1, p.x);
    y1 = std::max(y1, p.y);
  }
  return {x0, y0, x1 - x0, y1 - y0};
}

double ShortestSide(const std::vector<cv::Point2d>& outline) {
  double shortest = std::numeric_limits<double>::infinity();
  for (int k = 0; k < 4; ++k) shortest = std::min(shortest, cv::norm(outline[k] - outline[(k + 1) % 4]));
  return shortest;
}

}  // namespace

double AllowedOffset(double side_px, const RoiOptions& options) {
  return std::max(options.max_offset_px, options.max_offset_fraction * side_px);
}

void RoiOptions::Check() const {
  Require(padding_fraction >= 0.0, "padding_fraction must be non-negative");
  Require(padding_px >= 0, "padding_px must be non-negative");
  Require(alignment >= 1, "alignment must be at least 1");
  Require(min_module_px > 0.0, "min_module_px must be positive");
  Require(border_px >= 0, "border_px must be non-negative");
  Require(max_area_fraction > 0.0, "max_area_fraction must be positive");
  Require(max_offset_px > 0.0 && max_offset_fraction >= 0.0, "max_offset_px must be positive, "
                                                             "max_offset_fraction non-negative");
  Require(edge_points >= 1, "edge_points must be at least 1");
  Require(target_module_px >= 0.0, "target_module_px must be non-negative (0: never shrink)");
  Require(max_downscale >= 1, "max_downscale must be at least 1");
  Require(threshold_window_px == 0 || threshold_window_px >= 3, "threshold_window_px must be 0 or at least 3");
  Require(min_white_black_diff >= 0 && min_white_black_diff <= 255, "min_white_black_diff must be in [0, 255]");
}

const MarkerPrediction* PatternPlan::Find(int id) const {
  for (const auto& marker : markers) {
    if (marker.id == id) return &marker;
  }
  return nullptr;
}

namespace {

enum class Verdict { kSearch, kOutside, kFolded, kTooSmall, kUnresolvable };

struct Assessment {
  Verdict verdict = Verdict::kSearch;
  cv::Rect2d box;         // bounding box of the drawn square in the image
  double side_px = 0.0;   // its shortest side in the image
};

// Whether a marker drawn with `side` projector pixels around `centre` is worth searching.
Assessment Assess(const ProjectorHomography& homography, const CameraIntrinsics& lens, const cv::Rect& inner,
                  const cv::Point2d& centre, double side, int grid_cells, const RoiOptions& options,
                  const ResolutionLimit* limit) {
  Assessment a;
  const auto outline = SquareOutline(homography, lens, centre, side, options.edge_points);
  a.box = BoundingBox(outline);
  a.side_px = ShortestSide(outline);
  if (!(a.box.x >= inner.x && a.box.y >= inner.y && a.box.x + a.box.width <= inner.x + inner.width &&
        a.box.y + a.box.height <= inner.y + inner.height)) {
    a.verdict = Verdict::kOutside;
  } else if (homography.CrossesSurfaces(centre, side)) {
    a.verdict = Verdict::kFolded;
  } else if (a.side_px / grid_cells < options.min_module_px) {
    a.verdict = Verdict::kTooSmall;
  } else if (limit != nullptr && limit->Hopeless(a.side_px / grid_cells)) {
    a.verdict = Verdict::kUnresolvable;
  }
  return a;
}

// True when `max_scales` larger scales of the same MSM are worth searching too.
bool LargerScalesSuffice(const ProjectorHomography& homography, const CameraIntrinsics& lens, const cv::Rect& inner,
                         const cv::Point2d& centre, int id, int grid_cells, const ScaleSelection& selection,
                         const RoiOptions& options, const ResolutionLimit* limit) {
  if (selection.max_scales <= 0) return false;
  const double side = selection.sides[selection.current];
  int larger = 0;
  for (std::size_t s = 0; s < selection.sides.size(); ++s) {
    if (!(selection.sides[s] > side)) continue;
    const auto& omitted = selection.omitted[s];
    if (std::find(omitted.begin(), omitted.end(), id) != omitted.end()) continue;
    const Assessment a = Assess(homography, lens, inner, centre, selection.sides[s], grid_cells, options, limit);
    if (a.verdict == Verdict::kSearch && ++larger >= selection.max_scales) return true;
  }
  return false;
}

}  // namespace

PatternPlan PlanPattern(const ProjectorHomography& homography, const CameraIntrinsics& lens, cv::Size image_size,
                        const PatternMarkers& markers, const RoiOptions& options, const ResolutionLimit* limit,
                        const ScaleSelection* selection) {
  options.Check();
  if (!homography.valid()) throw std::logic_error("PlanPattern needs a valid homography");
  PatternPlan plan;
  const cv::Rect image(0, 0, image_size.width, image_size.height);
  const cv::Rect inner(options.border_px, options.border_px, image_size.width - 2 * options.border_px,
                       image_size.height - 2 * options.border_px);
  for (std::size_t i = 0; i < markers.ids.size(); ++i) {
    const Assessment a = Assess(homography, lens, inner, markers.centres[i], markers.side_px, markers.grid_cells,
                                options, limit);
    if (a.verdict == Verdict::kOutside) ++plan.outside;
    if (a.verdict == Verdict::kFolded) ++plan.folded;
    if (a.verdict == Verdict::kTooSmall) ++plan.too_small;
    if (a.verdict == Verdict::kUnresolvable) ++plan.unresolvable;
    if (a.verdict != Verdict::kSearch) continue;
    if (selection != nullptr && LargerScalesSuffice(homography, lens, inner, markers.centres[i], markers.ids[i],
                                                    markers.grid_cells, *selection, options, limit)) {
      ++plan.redundant;
      continue;
    }
    MarkerPrediction prediction;
    prediction.id = markers.ids[i];
    prediction.side_px = a.side_px;
    prediction.module_px = a.side_px / markers.grid_cells;
    prediction.centre =
        DistortPixels(lens, {ApplyHomography(homography.SurfaceAt(markers.centres[i]), markers.centres[i])})[0];
    const double quad_side = markers.side_px * markers.quad_cells / markers.grid_cells;
    const auto quad = SquareOutline(homography, lens, markers.centres[i], quad_side, 1);
    prediction.corners = {quad[0], quad[1], quad[2], quad[3]};
    if (options.target_module_px > 0.0) {
      const int factor = static_cast<int>(std::floor(prediction.module_px / options.target_module_px));
      prediction.downscale = std::clamp(factor, 1, options.max_downscale);
    }
    const cv::Rect2d& box = a.box;
    const double pad = std::max<double>(options.padding_px, options.padding_fraction * prediction.side_px);
    const int x0 = AlignDown(static_cast<int>(std::floor(box.x - pad)), options.alignment);
    const int y0 = AlignDown(static_cast<int>(std::floor(box.y - pad)), options.alignment);
    const int x1 = static_cast<int>(std::ceil(box.x + box.width + pad)) + 1;
    const int y1 = static_cast<int>(std::ceil(box.y + box.height + pad)) + 1;
    prediction.region = cv::Rect(x0, y0, x1 - x0, y1 - y0) & image;
    plan.markers.push_back(prediction);
  }
  // Detection costs grow with the pixels searched: the regions (each shrunk by its own
  // factor) against the whole frame (shrunk by the smallest factor).
  int smallest = options.max_downscale;
  for (const auto& marker : plan.markers) smallest = std::min(smallest, marker.downscale);
  double regions_cost = 0.0;
  for (const auto& marker : plan.markers) {
    regions_cost += static_cast<double>(marker.region.area()) / (marker.downscale * marker.downscale);
  }
  plan.whole_frame = regions_cost > options.max_area_fraction * image.area() / (smallest * smallest);
  return plan;
}

Detections DetectDownscaled(const MarkerDetector& detector, const cv::Mat& gray, int factor,
                            const DetectionTuning& tuning) {
  if (factor <= 1) return detector.Detect(gray, tuning);
  // Whole small pixels only: small pixel (i, j) covers pixels [f i, f i + f).
  const cv::Mat whole = gray(cv::Rect(0, 0, gray.cols - gray.cols % factor, gray.rows - gray.rows % factor));
  cv::Mat small;
  cv::resize(whole, small, cv::Size(whole.cols / factor, whole.rows / factor), 0, 0, cv::INTER_AREA);
  if (small.cols < kMinImageSide || small.rows < kMinImageSide) return detector.Detect(gray, tuning);
  Detections found = detector.Detect(small, tuning);
  // The centre of small pixel i (OpenCV convention) is at f i + (f - 1) / 2.
  const double offset = 0.5 * (factor - 1);
  for (Quad& quad : found.corners) {
    for (cv::Point2d& corner : quad) corner = corner * factor + cv::Point2d(offset, offset);
  }
  return found;
}

std::optional<Quad> DetectInRegion(const MarkerDetector& detector, const MarkerPrediction& marker,
                                   const RegionImage& region, const RoiOptions& options) {
  // The marker's size in a region is known: the detector is tuned for it.
  const DetectionTuning tuning{options.threshold_window_px, options.min_white_black_diff};
  const Detections found = DetectDownscaled(detector, region.gray, marker.downscale, tuning);
  const cv::Point2d origin(region.origin.x, region.origin.y);
  double best = AllowedOffset(marker.side_px, options);
  int chosen = -1;
  for (std::size_t k = 0; k < found.size(); ++k) {
    if (found.ids[k] != marker.id) continue;
    const double offset = cv::norm(DiagonalIntersection(found.corners[k]) + origin - marker.centre);
    if (offset <= best) {
      best = offset;
      chosen = static_cast<int>(k);
    }
  }
  if (chosen < 0) return std::nullopt;
  Quad quad = found.corners[chosen];
  for (auto& corner : quad) corner += origin;
  return quad;
}

Detections FilterDetections(const Detections& found, const std::vector<int>& ids, const PatternPlan* plan,
                            const RoiOptions& options, int* rejected) {
  std::map<int, int> seen;
  for (int id : found.ids) ++seen[id];
  Detections out;
  int dropped = 0;
  for (std::size_t k = 0; k < found.size(); ++k) {
    const int id = found.ids[k];
    const bool shown = std::find(ids.begin(), ids.end(), id) != ids.end();
    bool keep = shown && seen[id] == 1;
    if (keep && plan != nullptr) {
      const MarkerPrediction* marker = plan->Find(id);
      keep = marker != nullptr && cv::norm(DiagonalIntersection(found.corners[k]) - marker->centre) <=
                                      AllowedOffset(marker->side_px, options);
    }
    if (keep) {
      out.ids.push_back(id);
      out.corners.push_back(found.corners[k]);
    } else {
      ++dropped;
    }
  }
  if (rejected != nullptr) *rejected += dropped;
  return out;
}

}  // namespace calibproj::detect
