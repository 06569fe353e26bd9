#include "calibproj/ingest/detection_pipeline.h"

#include <time.h>

#include <algorithm>
#include <stdexcept>
#include <utility>

#include "calibproj/detect/marker_centre.h"

namespace calibproj::ingest {

DetectionPipeline::DetectionPipeline(const detect::MarkerFamily& family,
                                     const detect::DetectorOptions& detector_options,
                                     const detect::RoiOptions& roi_options, CornerOptions corner_options,
                                     int threads, int max_pending)
    : roi_options_(roi_options), corner_options_(std::move(corner_options)), max_pending_(max_pending) {
  if (threads < 1) throw std::invalid_argument("detection threads must be at least 1");
  if (max_pending < 1) throw std::invalid_argument("max pending detection jobs must be at least 1");
  for (int i = 0; i < threads; ++i) {
    detectors_.push_back(std::make_unique<detect::MarkerDetector>(family, detector_options));
  }
  for (const auto& detector : detectors_) workers_.emplace_back([this, d = detector.get()] { Work(*d); });
}

DetectionPipeline::~DetectionPipeline() { Stop(); }

void DetectionPipeline::Stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  work_ready_.notify_all();
  space_ready_.notify_all();
  for (auto& worker : workers_) {
    if (worker.joinable()) worker.join();
  }
}

void DetectionPipeline::RethrowLocked() {
  if (error_) std::rethrow_exception(error_);
}

void DetectionPipeline::Submit(DetectionJob job) {
  std::unique_lock<std::mutex> lock(mutex_);
  space_ready_.wait(lock, [&] { return static_cast<int>(queue_.size()) < max_pending_ || error_ || stopping_; });
  RethrowLocked();
  in_flight_.insert(job.pattern);
  queue_.push_back(std::move(job));
  work_ready_.notify_one();
}

std::vector<DetectionOutput> DetectionPipeline::Poll() {
  std::lock_guard<std::mutex> lock(mutex_);
  RethrowLocked();
  return std::exchange(finished_, {});
}

void DetectionPipeline::WaitForPatternsBefore(int pattern) {
  std::unique_lock<std::mutex> lock(mutex_);
  all_done_.wait(lock, [&] { return in_flight_.empty() || *in_flight_.begin() >= pattern || error_; });
  RethrowLocked();
}

std::vector<DetectionOutput> DetectionPipeline::Finish() {
  std::unique_lock<std::mutex> lock(mutex_);
  all_done_.wait(lock, [&] { return (queue_.empty() && running_ == 0) || error_; });
  RethrowLocked();
  return std::exchange(finished_, {});
}

detect::Quad DetectionPipeline::Undistorted(const detect::Quad& corners, const detect::RegionImage& region,
                                            double outward_fraction) const {
  const CornerOptions& o = corner_options_;
  if (o.refine_undistorted) {
    detect::UndistortedEdgeOptions edges = o.edges;
    edges.outward_fraction = outward_fraction;
    if (auto refined = detect::RefineUndistortedCorners(region.gray, region.origin, *o.lens, o.cells, corners, edges)) {
      return *refined;
    }
  }
  const auto points = o.lens->Undistort({corners.begin(), corners.end()});
  return {points[0], points[1], points[2], points[3]};
}

void DetectionPipeline::Work(const detect::MarkerDetector& detector) {
  while (true) {
    DetectionJob job;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      work_ready_.wait(lock, [&] { return !queue_.empty() || stopping_; });
      if (stopping_) return;
      job = std::move(queue_.front());
      queue_.pop_front();
      ++running_;
    }
    space_ready_.notify_one();
    DetectionOutput output;
    std::exception_ptr error;
    try {
      output = Run(detector, job);
    } catch (...) {
      error = std::current_exception();
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      --running_;
      in_flight_.erase(in_flight_.find(job.pattern));
      if (error && !error_) error_ = error;
      if (!error) finished_.push_back(std::move(output));
    }
    all_done_.notify_all();
    space_ready_.notify_all();
  }
}

namespace {

// CPU time of the calling thread: detection competes with decoding for the cores, so
// wall time would count the other threads' work too.
double ThreadSeconds() {
  timespec now{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &now);
  return static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec);
}

}  // namespace

DetectionOutput DetectionPipeline::Run(const detect::MarkerDetector& detector, const DetectionJob& job) const {
  const double started = ThreadSeconds();
  DetectionOutput output;
  output.pattern = job.pattern;
  output.whole_frame = job.whole_frame;
  output.explored = job.explore;
  output.first_frame = job.first_frame;
  output.frame_count = job.frame_count;
  if (job.has_plan) output.searched = job.plan.markers;
  if (job.whole_frame) {
    const detect::Detections found = detect::DetectDownscaled(detector, job.regions.at(0).gray, job.downscale);
    const bool predicted = job.has_plan && !job.explore;
    output.detections =
        detect::FilterDetections(found, job.ids, predicted ? &job.plan : nullptr, roi_options_, &output.rejected);
    for (const detect::Quad& corners : output.detections.corners) {
      output.undistorted.push_back(Undistorted(corners, job.regions.at(0), job.outward_fraction));
    }
  } else {
    if (job.regions.size() != job.plan.markers.size()) {
      throw std::invalid_argument("one region image per planned marker");
    }
    // In id order, as the detectors' results are sorted.
    std::vector<std::size_t> order(job.plan.markers.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(),
                     [&](std::size_t a, std::size_t b) { return job.plan.markers[a].id < job.plan.markers[b].id; });
    for (const std::size_t i : order) {
      detect::Quad distorted, undistorted;
      bool verified = false;
      if (!DetectPlanned(detector, job.plan.markers[i], job.regions[i], job.outward_fraction, &distorted,
                         &undistorted, &verified)) {
        continue;
      }
      output.verified += verified ? 1 : 0;
      output.detections.ids.push_back(job.plan.markers[i].id);
      output.detections.corners.push_back(distorted);
      output.undistorted.push_back(undistorted);
    }
  }
  output.seconds = ThreadSeconds() - started;
  return output;
}

bool DetectionPipeline::DetectPlanned(const detect::MarkerDetector& detector, const detect::MarkerPrediction& marker,
                                      const detect::RegionImage& region, double outward_fraction,
                                      detect::Quad* distorted, detect::Quad* undistorted, bool* verified) const {
  if (const std::optional<detect::Quad> found = AtPrediction(marker, region, outward_fraction)) {
    *verified = true;
    *undistorted = *found;
    const auto points = corner_options_.lens->Distort({found->begin(), found->end()});
    *distorted = {points[0], points[1], points[2], points[3]};
    return true;
  }
  const std::optional<detect::Quad> quad = detect::DetectInRegion(detector, marker, region, roi_options_);
  if (!quad) return false;
  *distorted = *quad;
  *undistorted = Undistorted(*quad, region, outward_fraction);
  return true;
}

std::optional<detect::Quad> DetectionPipeline::AtPrediction(const detect::MarkerPrediction& marker,
                                                            const detect::RegionImage& region,
                                                            double outward_fraction) const {
  const CornerOptions& o = corner_options_;
  if (!o.verify_predicted || !o.refine_undistorted || !o.bits || marker.id < 0 ||
      marker.id >= static_cast<int>(o.bits->size())) {
    return std::nullopt;
  }
  detect::UndistortedEdgeOptions edges = o.edges;
  edges.outward_fraction = outward_fraction;
  const std::optional<detect::Quad> refined =
      detect::RefineUndistortedCorners(region.gray, region.origin, *o.lens, o.cells, marker.corners, edges);
  if (!refined) return std::nullopt;
  // As far from the prediction as a detector's find may be.
  const cv::Point2d centre = o.lens->Distort({detect::DiagonalIntersection(*refined)})[0];
  if (!(cv::norm(centre - marker.centre) <= detect::AllowedOffset(marker.side_px, roi_options_))) return std::nullopt;
  if (!detect::ShowsMarker(region.gray, region.origin, *o.lens, *refined, (*o.bits)[marker.id], o.cells,
                           o.verification)) {
    return std::nullopt;
  }
  return refined;
}

std::shared_ptr<const std::vector<cv::Mat>> ProjectedBits(const detect::MarkerFamily& family, int count,
                                                          bool inverted) {
  auto bits = std::make_shared<std::vector<cv::Mat>>();
  const int ids = std::min(count, detect::MarkerIdCount(family));
  for (int id = 0; id < ids; ++id) bits->push_back(detect::ProjectedCells(family, id, inverted));
  return bits;
}

}  // namespace calibproj::ingest
