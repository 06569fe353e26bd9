#pragma once
// The detections of one camera checked against the homographies of the surfaces the
// projection lands on.
//
// Every MSM centre lies on the floor, or on a table or cart left in the projection, so
// a projector-to-image homography per surface maps each marker's projector centre to
// its undistorted image centre. A marker decoded with a wrong id (bits lost to
// saturation, a stain or compression) or taken from a frame of another pattern lands
// far from where the homography of the others puts it. A RANSAC homography over every
// detection (the dominant surface) keeps those within threshold_px; then, among the
// rest, up to max_surfaces - 1 more homographies (other surfaces) keep theirs, each
// with min_points detections at min_positions distinct image places at least. When too
// few agree with the first, none of the camera's detections can be trusted.
//
// The threshold leaves room for lenses known only roughly, whose residuals vary slowly
// over the image. A marker partly hidden by a table, or cut by its shadow, still decodes
// but with its centre displaced by a pixel or two: it stands out against its neighbours.
// So each detection's residual is compared with the median residual of its nearest
// detections of other markers on its surface.

#include <opencv2/core.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace calibproj::detect {

struct ConsistencyOptions {
  double threshold_px = 3.0;  // largest distance from the homography's prediction
  // Detections needed for a check; fewer are kept unchecked, but for those that repeat
  // at one image place for three different MSMs or more (a static pattern).
  int min_points = 8;
  double min_share = 0.3;     // share that must agree, else every detection is dropped
  // Distinct places the agreeing detections must cover (image points farther apart than
  // 4 threshold_px, or marker positions: whichever count is larger): a homography fits
  // any few places, so a static pattern of the floor decoded as one marker in every
  // array would pass unchecked.
  int min_positions = 3;
  int max_surfaces = 3;  // the floor and up to this many - 1 other surfaces
  // Local check: a detection whose residual differs from the median of those of its
  // local_neighbours nearest other markers (image pixels) by more than local_sigmas robust
  // standard deviations of all such differences, and by more than min_local_px, is
  // dropped (local_neighbours 0: no local check).
  int local_neighbours = 8;
  double local_sigmas = 5.0;
  double min_local_px = 0.5;
  std::uint64_t seed = 0;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

struct ConsistencyResult {
  std::vector<bool> keep;  // per detection
  bool checked = false;    // enough detections for a check
  int rejected = 0;
  std::string problem;     // set when every detection was dropped
};

// `projector[i]` and `image[i]`: projector centre and undistorted image centre of
// detection i; `position[i]`: its marker's position in the array (grid cell).
ConsistencyResult CheckFloorConsistency(const std::vector<cv::Point2d>& projector,
                                        const std::vector<cv::Point2d>& image, const std::vector<int>& position,
                                        const ConsistencyOptions& options);

}  // namespace calibproj::detect
