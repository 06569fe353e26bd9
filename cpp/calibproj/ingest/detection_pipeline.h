#pragma once
// Marker detection on worker threads while the video keeps decoding.
//
// The decoding thread submits one job per pattern (a whole grey frame, or the grey
// regions of its markers) and collects finished jobs when it likes. At most
// `max_pending` jobs wait at any time (Submit blocks beyond), so memory stays bounded
// whatever the video length. Each worker owns its detector (libapriltag's detector is
// not re-entrant).

#include <condition_variable>
#include <deque>
#include <exception>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <thread>
#include <vector>

#include "calibproj/detect/lens.h"
#include "calibproj/detect/marker_detector.h"
#include "calibproj/detect/marker_verification.h"
#include "calibproj/detect/roi.h"
#include "calibproj/detect/undistorted_edges.h"

namespace calibproj::ingest {

struct DetectionJob {
  int pattern = -1;
  std::vector<int> ids;               // ids the pattern shows
  bool whole_frame = true;            // regions[0] is the whole frame
  int downscale = 1;                  // the whole frame is detected shrunk by this factor
  bool has_plan = false;              // plan holds predictions (the homography was known)
  bool explore = false;               // keep markers found far from their prediction
  detect::PatternPlan plan;
  std::vector<detect::RegionImage> regions;
  int first_frame = -1;
  int frame_count = 0;
  // How far edge profiles may reach out of a marker (share of a module): a share of
  // the gap to the next marker of the pattern.
  double outward_fraction = 0.45;
};

struct DetectionOutput {
  int pattern = -1;
  bool whole_frame = true;
  bool explored = false;          // the job explored (markers kept wherever found)
  int first_frame = -1;
  int frame_count = 0;
  detect::Detections detections;  // whole-image distorted pixels, filtered
  // Per detection, its corners in undistorted pixels (refined, or merely undistorted).
  std::vector<detect::Quad> undistorted;
  int rejected = 0;               // detections dropped (unexpected id, duplicate, off prediction)
  int verified = 0;               // markers found at their predicted corners
  std::vector<detect::MarkerPrediction> searched;  // the planned markers, when there was a plan
  double seconds = 0.0;           // CPU time of the detection
};

// How detected corners become undistorted corners.
struct CornerOptions {
  std::shared_ptr<const detect::LensTables> lens;
  int cells = 1;  // modules across the detected square
  // Refine by straight edge lines in undistorted pixels (undistorted_edges.h); false
  // undistorts the detector's corners.
  bool refine_undistorted = true;
  detect::UndistortedEdgeOptions edges;
  // Markers planned in regions looked for at their predicted corners first
  // (marker_verification.h; needs refine_undistorted), the detector searching only the
  // regions where that fails.
  bool verify_predicted = false;
  detect::VerificationOptions verification;
  // The cells of marker id i as projected (inverted when the sequence inverts its
  // markers), for every id a pattern may show; ids beyond are left to the detector.
  std::shared_ptr<const std::vector<cv::Mat>> bits;
};

// The projected cells of the ids 0 .. count - 1 of `family`.
std::shared_ptr<const std::vector<cv::Mat>> ProjectedBits(const detect::MarkerFamily& family, int count,
                                                          bool inverted);

class DetectionPipeline {
 public:
  DetectionPipeline(const detect::MarkerFamily& family, const detect::DetectorOptions& detector_options,
                    const detect::RoiOptions& roi_options, CornerOptions corner_options, int threads,
                    int max_pending);
  ~DetectionPipeline();
  DetectionPipeline(const DetectionPipeline&) = delete;
  DetectionPipeline& operator=(const DetectionPipeline&) = delete;

  // Queues a job; blocks while max_pending jobs wait. Rethrows a worker's exception.
  void Submit(DetectionJob job);
  // Jobs finished since the last call (in completion order).
  std::vector<DetectionOutput> Poll();
  // Waits until every job of a pattern before `pattern` has finished.
  void WaitForPatternsBefore(int pattern);
  // Waits for every queued job and returns the remaining outputs.
  std::vector<DetectionOutput> Finish();

 private:
  void Work(const detect::MarkerDetector& detector);
  DetectionOutput Run(const detect::MarkerDetector& detector, const DetectionJob& job) const;
  void RethrowLocked();
  void Stop();

  detect::Quad Undistorted(const detect::Quad& corners, const detect::RegionImage& region,
                           double outward_fraction) const;
  // The detection of planned marker `marker` in `region`: at its predicted corners
  // when they verify (*verified set), else by the detector; false when it is not found.
  bool DetectPlanned(const detect::MarkerDetector& detector, const detect::MarkerPrediction& marker,
                     const detect::RegionImage& region, double outward_fraction, detect::Quad* distorted,
                     detect::Quad* undistorted, bool* verified) const;
  std::optional<detect::Quad> AtPrediction(const detect::MarkerPrediction& marker, const detect::RegionImage& region,
                                           double outward_fraction) const;

  detect::RoiOptions roi_options_;
  CornerOptions corner_options_;
  int max_pending_;
  std::vector<std::unique_ptr<detect::MarkerDetector>> detectors_;
  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable work_ready_, space_ready_, all_done_;
  std::deque<DetectionJob> queue_;
  std::vector<DetectionOutput> finished_;
  std::multiset<int> in_flight_;  // patterns of the jobs queued or running
  int running_ = 0;
  bool stopping_ = false;
  std::exception_ptr error_;
};

}  // namespace calibproj::ingest
