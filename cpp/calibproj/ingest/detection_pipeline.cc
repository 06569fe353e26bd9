#include "calibproj/ingest/detection_pipeline.h"

#include <time.h>

#include <stdexcept>
#include <utility>

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
  output.first_frame = job.first_frame;
  output.frame_count = job.frame_count;
  if (job.has_plan) output.searched = job.plan.markers;
  if (job.whole_frame) {
    const detect::Detections found = detect::DetectDownscaled(detector, job.regions.at(0).gray, job.downscale);
    const bool predicted = job.has_plan && !job.explore;
    output.detections =
        detect::FilterDetections(found, job.ids, predicted ? &job.plan : nullptr, roi_options_, &output.rejected);
  } else {
    output.detections = detect::DetectInRegions(detector, job.plan, job.regions, roi_options_);
  }
  for (std::size_t k = 0; k < output.detections.size(); ++k) {
    // The region the marker was found in: the whole frame, or its own region.
    std::size_t region = 0;
    if (!job.whole_frame) {
      while (job.plan.markers[region].id != output.detections.ids[k]) ++region;
    }
    output.undistorted.push_back(Undistorted(output.detections.corners[k], job.regions[region], job.outward_fraction));
  }
  output.seconds = ThreadSeconds() - started;
  return output;
}

}  // namespace calibproj::ingest
