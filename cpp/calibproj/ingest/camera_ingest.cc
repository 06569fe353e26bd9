#include "calibproj/ingest/camera_ingest.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cstdio>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <stdexcept>
#include <thread>
#include <unordered_map>
#include <unordered_set>
#include <utility>

#include "calibproj/common/limits.h"
#include "calibproj/detect/floor_consistency.h"
#include "calibproj/detect/marker_centre.h"
#include "calibproj/detect/surface_fit.h"
#include "calibproj/ingest/detection_pipeline.h"
#include "calibproj/ingest/option_table.h"
#include "calibproj/sync/code_search.h"
#include "calibproj/video/frame_ring.h"
#include "calibproj/video/luma.h"

namespace calibproj::ingest {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr int kProgressInterval = 25;
// Decoded frames kept for the start code search, and patterns waiting for detection,
// at most: each holds whole frames.
constexpr int kMaxHeldFrames = 1024;
// The adaptive bootstrap trusts a magnification only from an MSM seen at two of its
// scales: concentric within this share of the smaller side, with sides in the ratio
// of the scales within this tolerance. A single decoded quad may be a floor marking
// that happens to decode; one 3x too large once shrank every later frame until no real
// marker survived (measured: a 60 fps camera under room light and floor texture lost
// all its 1,500 markers).
constexpr double kConcentricShare = 0.25;
constexpr double kScaleRatioTolerance = 0.25;

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument("ingest options: " + message);
}

enum class PatternStatus { kNotSeen, kSkipped, kSubmitted };

// The frames of one pattern being collected (and averaged) before detection.
struct PendingPattern {
  int pattern = -1;
  bool skip = false;
  DetectionJob job;
  std::vector<cv::Rect> rects;
  std::vector<cv::Mat> sums;  // CV_16U accumulators when averaging
  std::vector<int> frames;
};

video::SourceOptions Decoding(video::SourceOptions source, int decode_threads) {
  source.decode_threads = decode_threads;
  return source;
}

double MeanSide(const detect::Quad& quad) {
  double total = 0.0;
  for (int k = 0; k < 4; ++k) total += cv::norm(quad[k] - quad[(k + 1) % 4]);
  return 0.25 * total;
}

class CameraIngest {
 public:
  CameraIngest(const std::string& path, const SequenceDescription& sequence, const formats::CameraIntrinsics& camera,
               const std::string& intrinsics_source,
               const IngestOptions& options, const ProgressCallback& progress, const video::SourceOptions& source)
      : path_(path),
        sequence_(sequence),
        camera_(camera),
        intrinsics_source_(intrinsics_source),
        reader_(path, Decoding(source, options.decode_threads)),
        options_(Prepared(options, sequence, reader_.info().fps)),
        progress_(progress),
        family_(detect::ParseMarkerFamily(sequence.markers.spec)),
        timeline_(sequence.LightLevels()),
        nominal_rate_(reader_.info().fps / sequence.fps),
        luma_(options_.luma_gamma, options_.mean_row_step),
        ring_(options_.lookback_frames),
        clock_(1.0 / reader_.info().fps, options_.max_frame_gap_s, options_.use_timestamps, path),
        homography_(cv::Size(reader_.info().width, reader_.info().height), options_.homography),
        resolution_(options_.resolution),
        pipeline_(family_, options_.detector, options_.roi,
                  CornerOptions{std::make_shared<const detect::LensTables>(
                                    camera, cv::Size(reader_.info().width, reader_.info().height)),
                                sequence.markers.quad_cells, options_.refine_undistorted, options_.edges,
                                options_.refine_undistorted && options_.verify_predicted,
                                options_.verification,
                                ProjectedBits(family_, sequence.markers_per_array, sequence.markers.inverted)},
                  options_.detection_threads, options_.max_pending_jobs),
        status_(sequence.patterns.size(), PatternStatus::kNotSeen),
        used_frames_(sequence.patterns.size()) {
    CheckResolution();
    tracker_ = std::make_unique<sync::CodeTracker>(
        timeline_, sync::CodeWindow(timeline_, sequence.start_code, options_.sync), nominal_rate_,
        options_.sync.search, options_.sync.min_correlation, options_.sync.guard_samples);
    result_.video = reader_.info();
    band_means_.assign(options_.readout_bands, 0.0);
    band_signals_.assign(options_.readout_bands, {});
    result_.scales.resize(sequence.scales.size());
    for (const PatternSpec& p : sequence.patterns) ++result_.scales[p.scale_index].patterns;
  }

  CameraIngestResult Run() {
    const auto started = std::chrono::steady_clock::now();
    bool seen_end = false;  // every frame the sync and the picks need was decoded
    while (reader_.Grab()) {
      const int decoded = reader_.frame_index() + 1;
      if (progress_ && decoded % kProgressInterval == 1) progress_(decoded, reader_.info().frame_count);
      const int frame = clock_.Place(reader_.timestamp());
      if (frame < 0) continue;  // a second frame in one slot: the first one counts
      // Slots the camera dropped are unmeasured.
      result_.signal.resize(frame, kNaN);
      for (auto& band : band_signals_) band.resize(frame, kNaN);
      converted_ = false;
      if (started_) {
        OnFrameAfterStart(frame);
        // Past the end code's window and the last planned pick nothing is used: a
        // recording that runs on after the projection is not decoded further.
        if (frame >= last_needed_frame_) {
          seen_end = true;
          break;
        }
      } else {
        OnFrameBeforeStart(frame);
      }
    }
    if (!seen_end && !reader_.end_reason().empty()) {
      // A live source that stalled or was stopped: the projection is not all there.
      throw std::runtime_error(path_ + ": the source " + reader_.end_reason() + " before " +
                               (started_ ? "the end of the projection" : "the start light code was seen"));
    }
    result_.frames_decoded = reader_.frame_index() + 1;
    result_.timing = clock_.Stats();
    if (progress_) progress_(result_.frames_decoded, result_.frames_decoded);
    if (!started_) ThrowStartNotFound();
    SubmitPending();
    AbsorbBefore(static_cast<int>(sequence_.patterns.size()));
    result_.sync = sync::SynchroniseFromStart(result_.signal, timeline_, sequence_.start_code, sequence_.end_code,
                                              start_, nominal_rate_, options_.sync, path_);
    ApplyReadout(&result_.sync);
    DropUncleanPatterns();
    ThrowIfEveryPatternDropped();
    Summarise();
    result_.band_signals = std::move(band_signals_);
    result_.seconds_total = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    return std::move(result_);
  }

 private:
  // The options with what the sequence fixes (marker polarity) filled in.
  static IngestOptions Prepared(IngestOptions options, const SequenceDescription& sequence, double video_fps) {
    sequence.Check();
    options.detector.aruco.inverted = sequence.markers.inverted;
    options.detector.apriltag.inverted = sequence.markers.inverted;
    if (options.refine_undistorted) {
      // The undistorted edge fit refines the detector's raw corners.
      options.detector.aruco.refinement.method = detect::CornerRefinement::kNone;
      options.detector.apriltag.refinement.method = detect::CornerRefinement::kNone;
    }
    if (options.exposure_s > 0.0) {
      const double exposure = std::min(options.exposure_s * video_fps, 1.0);
      if (options.readout_bands > 0 && options.unmeasured_readout_frames > 0.0) {
        // A rolling shutter's whole frame sees the light from its first row's exposure
        // to its last row's: the known exposure is a row's, the frame's lasts up to the
        // readout longer. The bands are fitted with the row's (RowFitOptions).
        options.sync.fit.min_exposure = exposure;
        options.sync.fit.max_exposure = std::min(1.0, exposure + options.unmeasured_readout_frames);
      } else {
        options.sync.fit.fixed_exposure = exposure;
      }
    }
    // One knob for the surfaces: those planned with and those kept by the check.
    options.homography.max_surfaces = options.consistency.max_surfaces;
    options.Check();
    return options;
  }

  void CheckResolution() const {
    if (!camera_.has_resolution) return;
    const cv::Size expected(static_cast<int>(camera_.width), static_cast<int>(camera_.height));
    const auto& info = reader_.info();
    if (expected.width != info.width || expected.height != info.height) {
      throw std::invalid_argument(path_ + ": frames are " + std::to_string(info.width) + "x" +
                                  std::to_string(info.height) + " but the intrinsics (" + intrinsics_source_ +
                                  ") are for " + std::to_string(expected.width) + "x" +
                                  std::to_string(expected.height));
    }
  }

  // ------------------------------------------------------------------ decoding

  cv::Mat Gray() {
    if (!converted_) {
      converted_ = true;
      ++result_.frames_converted;
    }
    return reader_.Gray();
  }

  void OnFrameBeforeStart(int frame) {
    const video::LumaPlane luma = reader_.Luma();
    Measure(luma);
    ring_.Push(frame, luma);
    // Every search_interval slots (slot 0, search_interval, ... when no frame is dropped).
    if (frame >= last_search_ + options_.search_interval) {
      last_search_ = frame - frame % options_.search_interval;
      if (tracker_->Update(result_.signal)) OnStartFound();
    }
  }

  // Mean luma of the frame (and of its bands) appended to the signals.
  void Measure(const video::LumaPlane& luma) {
    result_.signal.push_back(luma_.Mean(luma, &band_means_));
    for (std::size_t b = 0; b < band_means_.size(); ++b) band_signals_[b].push_back(band_means_[b]);
  }

  void OnStartFound() {
    start_ = sync::FitCode(result_.signal, timeline_, sequence_.start_code, tracker_->best(), nominal_rate_,
                           options_.sync);
    // The start code's conservative window (covering every row of a rolling shutter),
    // carried on at the nominal rate.
    const sync::ReadoutEstimate readout = EstimateReadout({sync::CodeWindow(timeline_, sequence_.start_code,
                                                                            options_.sync)}, start_.map);
    const sync::FrameMap window =
        ReadoutApplies(readout) ? sync::CoverRows(start_.window_map, readout, 1.0) : start_.window_map;
    const double first = sequence_.start_code.first_frame;
    provisional_ = sync::FrameMap{window.CameraFrame(first) - nominal_rate_ * first, nominal_rate_, window.exposure};
    PlanPicks();
    PlanEndCodeMeans();
    last_needed_frame_ = end_means_last_;
    if (!frame_pattern_.empty()) last_needed_frame_ = std::max(last_needed_frame_, frame_pattern_.rbegin()->first);
    started_ = true;
    for (const auto& [index, luma] : ring_.frames()) {
      const auto pick = frame_pattern_.find(index);
      if (pick != frame_pattern_.end()) {
        HandlePick(index, pick->second, [&]() {
          ++result_.frames_converted;
          return video::FullRangeGray(luma);
        });
      }
    }
    ring_.Clear();
  }

  void OnFrameAfterStart(int frame) {
    const bool measure = frame >= end_means_first_ && frame <= end_means_last_;
    const auto pick = frame_pattern_.find(frame);
    if (measure) {
      Measure(reader_.Luma());  // the grey image is made only for the frames detected on
    } else {
      result_.signal.push_back(kNaN);
      for (auto& band : band_signals_) band.push_back(kNaN);
    }
    if (pick != frame_pattern_.end()) {
      HandlePick(frame, pick->second, [&]() { return Gray(); });
    }
  }

  // Frames to detect on, per pattern, from the start code's conservative exposure
  // window and the nominal rate; the slack covers the clock drift since the code.
  // The most central clean frames are wanted; the clean frames after the first of
  // them stand in for any that the camera dropped.
  void PlanPicks() {
    const video::PickOptions& pick = options_.pick;
    picks_.assign(sequence_.patterns.size(), {});
    wanted_.assign(sequence_.patterns.size(), 0);
    for (std::size_t p = 0; p < sequence_.patterns.size(); ++p) {
      const PatternSpec& pattern = sequence_.patterns[p];
      const double begin = pattern.first_frame, end = pattern.last_frame + 1.0;
      double slack = pick.max_clock_drift * std::abs(begin - sequence_.start_code.first_frame);
      std::vector<int> central = video::PickFrames(provisional_, begin, end, pick.margin, slack, pick.average_frames);
      if (central.empty()) {
        slack = 0.0;
        central = video::PickFrames(provisional_, begin, end, pick.margin, slack, 1);
      }
      if (central.empty()) continue;
      const int candidates = pick.average_frames + 2 * pick.spare_frames;
      for (int frame : video::PickFrames(provisional_, begin, end, pick.margin, slack, candidates)) {
        const int limit = static_cast<int>(central.size()) + pick.spare_frames;
        if (frame >= central.front() && static_cast<int>(picks_[p].size()) < limit) picks_[p].push_back(frame);
      }
      wanted_[p] = static_cast<int>(central.size());
      for (int frame : picks_[p]) frame_pattern_.emplace(frame, static_cast<int>(p));
    }
  }

  // Frames whose mean luma the end code search needs.
  void PlanEndCodeMeans() {
    const sync::FrameWindow window = sync::CodeWindow(timeline_, sequence_.end_code, options_.sync);
    const double spread =
        options_.sync.max_rate_deviation * nominal_rate_ * (window.end - sequence_.start_code.first_frame) + 3.0;
    end_means_first_ = static_cast<int>(std::floor(provisional_.CameraFrame(window.begin) - spread));
    end_means_last_ = static_cast<int>(std::ceil(provisional_.CameraFrame(window.end) + spread));
  }

  [[noreturn]] void ThrowStartNotFound() {
    // The full search gives the message (best correlation seen); it cannot succeed
    // where the incremental one failed unless the code ends with the video.
    sync::Synchronise(result_.signal, timeline_, sequence_.start_code, sequence_.end_code, nominal_rate_,
                      options_.sync, path_);
    throw std::runtime_error(path_ + ": the start light code ends too close to the end of the video");
  }

  sync::ReadoutEstimate EstimateReadout(const std::vector<sync::FrameWindow>& windows, const sync::FrameMap& map) {
    if (band_signals_.empty()) return {};
    return sync::EstimateReadout(band_signals_, timeline_, windows, map, RowFitOptions());
  }

  // The code fit of a band of rows: with the known exposure, which is a row's.
  sync::CodeFitOptions RowFitOptions() const {
    sync::CodeFitOptions fit = options_.sync.fit;
    const double video_fps = nominal_rate_ * sequence_.fps;
    if (options_.exposure_s > 0.0) fit.fixed_exposure = std::min(options_.exposure_s * video_fps, 1.0);
    return fit;
  }

  // The readout from both codes; a rolling shutter's frame map is its first row's.
  void ApplyReadout(sync::SyncResult* sync) {
    const std::vector<sync::FrameWindow> windows{sync::CodeWindow(timeline_, sequence_.start_code, options_.sync),
                                                 sync::CodeWindow(timeline_, sequence_.end_code, options_.sync)};
    sync->readout = EstimateReadout(windows, sync->map);
    RefitWithKnownExposure(windows, sync);
    // A known exposure is reported as given (a row's), whatever the whole frame's fit.
    if (options_.exposure_s > 0.0) sync->map.exposure = RowFitOptions().fixed_exposure;
    if (!ReadoutApplies(sync->readout)) {
      // A readout known too poorly to move the map: the map is that of the rows that
      // see the projection (near the middle when it fills the image), up to that share
      // of the readout from the first row's, and as far from the last row's.
      const double readout_bound = sync->readout.valid
                                       ? std::abs(sync->readout.readout) + 2.0 * sync->readout.readout_sigma
                                       : options_.unmeasured_readout_frames;
      const double row = sync->readout.signal_row;
      // Added, not the larger of the two: those rows' offset is itself uncertain.
      sync->offset_uncertainty += std::max(row, 1.0 - row) * readout_bound;
      return;
    }
    sync->readout.applied = true;
    sync->map.offset = sync->readout.first_row_offset;
    if (sync->readout.rate > 0.0) sync->map.rate = sync->window_map.rate = sync->readout.rate;
    sync->map.exposure = sync->readout.exposure;
    sync->offset_uncertainty = std::max(sync->offset_uncertainty, sync->readout.offset_sigma);
    // One sigma of margin: the picks were made from the same kind of estimate, and the
    // floor-consistency check catches a frame whose last rows saw the next pattern.
    sync->window_map = sync::CoverRows(sync->window_map, sync->readout, 1.0);
  }

  // With a known exposure the whole frame was fitted with exposures up to the largest
  // readout longer; a measured readout that bounds that tighter (a global shutter's,
  // near 0) fits the whole frame again with its bound, so that the known exposure
  // pins the offset as it would without any rolling shutter.
  void RefitWithKnownExposure(const std::vector<sync::FrameWindow>& windows, sync::SyncResult* sync) const {
    const sync::ReadoutEstimate& readout = sync->readout;
    const sync::CodeFitOptions& fit = options_.sync.fit;
    if (!(options_.exposure_s > 0.0) || fit.fixed_exposure > 0.0 || !readout.valid) return;
    const double bound = std::abs(readout.readout) + 2.0 * readout.readout_sigma;
    if (!(fit.min_exposure + bound < fit.max_exposure)) return;
    sync::CodeFitOptions tighter = fit;
    tighter.max_exposure = fit.min_exposure + bound;
    const sync::CodeFit joint = sync::FitCodeWindows(result_.signal, timeline_, windows, sync->map, true, tighter);
    sync->map = joint.map;
    sync->window_map = joint.window_map;
    sync->offset_uncertainty = joint.offset_uncertainty;
    sync->sharp = joint.sharp;
    sync->rms = joint.rms;
  }

  bool ReadoutApplies(const sync::ReadoutEstimate& readout) const {
    return sync::Applicable(readout, options_.readout_sigmas, options_.max_readout_sigma);
  }

  // ----------------------------------------------------------------- patterns

  template <typename ImageFn>
  void HandlePick(int frame, int pattern, ImageFn image) {
    if (status_[pattern] == PatternStatus::kSubmitted) return;  // enough frames already
    if (pending_.pattern != pattern) {
      SubmitPending();
      BeginPattern(pattern);
    }
    if (pending_.skip) return;
    AddFrame(frame, image());
    if (static_cast<int>(pending_.frames.size()) == wanted_[pattern] || frame == picks_[pattern].back()) {
      SubmitPending();
    }
  }

  void BeginPattern(int index) {
    // Until the homography is known every pattern costs a whole-frame detection:
    // waiting for the ones under way gives it as early as possible.
    AbsorbBefore(homography_.valid() ? index - options_.planning_lag : index);
    homography_.Update();
    pending_ = PendingPattern{};
    pending_.pattern = index;
    const detect::PatternMarkers markers = sequence_.Markers(index);
    ScaleStats& stats = result_.scales[sequence_.patterns[index].scale_index];
    DetectionJob& job = pending_.job;
    job.pattern = index;
    job.ids = markers.ids;
    job.outward_fraction = std::min(options_.edges.outward_fraction,
                                    options_.edge_gap_share * sequence_.GapModules(index));
    const cv::Rect whole(0, 0, reader_.info().width, reader_.info().height);
    if (!homography_.valid()) {
      job.whole_frame = true;
      job.downscale = BootstrapDownscale(sequence_.patterns[index]);
      stats.searched += static_cast<int>(markers.ids.size());
      pending_.rects = {whole};
      return;
    }
    job.has_plan = true;
    const detect::ScaleSelection selection = Selection(index);
    job.plan = detect::PlanPattern(homography_, camera_, whole.size(), markers, options_.roi,
                                   options_.learn_resolution ? &resolution_ : nullptr, &selection);
    stats.too_small += job.plan.too_small;
    stats.outside += job.plan.outside;
    stats.folded += job.plan.folded;
    stats.unresolvable += job.plan.unresolvable;
    stats.redundant += job.plan.redundant;
    job.explore = Explores(index);
    if (job.explore) {
      last_explored_array_ = sequence_.patterns[index].array;
      ++explorations_;
    }
    if (job.plan.markers.empty() && !job.explore) {
      pending_.skip = true;
      status_[index] = PatternStatus::kSkipped;
      ++stats.skipped_patterns;
      return;
    }
    stats.searched += static_cast<int>(job.plan.markers.size());
    job.whole_frame = !options_.use_roi || job.plan.whole_frame || job.explore;
    if (options_.use_roi && job.whole_frame) {
      // Too many large markers for regions: the whole frame, shrunk for the smallest
      // (exploring where none is expected: shrunk as before the homography).
      int factor =
          job.plan.markers.empty() ? BootstrapDownscale(sequence_.patterns[index]) : options_.roi.max_downscale;
      for (const auto& marker : job.plan.markers) factor = std::min(factor, marker.downscale);
      job.downscale = factor;
    }
    if (job.whole_frame) {
      pending_.rects = {whole};
    } else {
      for (const auto& marker : job.plan.markers) pending_.rects.push_back(marker.region);
    }
  }

  // True for one of the explore_scales largest scales of an array explore_gap_ arrays
  // after the last explored one: its whole frame is searched and every marker found kept
  // wherever it is, so that markers on a surface not yet known (a table top, planned
  // where the floor would have put them) are found. The explorations take the largest
  // scales in turn: the largest are found from afar, smaller ones fit on a narrow table.
  bool Explores(int index) const {
    if (options_.explore_interval <= 0) return false;
    const PatternSpec& pattern = sequence_.patterns[index];
    if (pattern.array < last_explored_array_ + std::max(explore_gap_, options_.explore_interval)) return false;
    int larger = 0;
    for (const PatternSpec& other : sequence_.patterns) {
      if (other.array == pattern.array && other.marker_side_px > pattern.marker_side_px) ++larger;
    }
    return larger == explorations_ % options_.explore_scales;
  }

  // After an explored pattern: markers found off the known surfaces, or on any but the
  // dominant one (the floor; a table top's markers are planned well only where its own
  // correspondences are dense), keep the explorations frequent; none, in explore_scales
  // explorations in a row, spaces them out (doubling the interval each time, up to
  // explore_max_interval): a room with nothing but the floor stops paying whole frames.
  void AdaptExploring(const DetectionOutput& output) {
    const PatternSpec& pattern = sequence_.patterns[output.pattern];
    bool beyond_floor = false;
    for (std::size_t k = 0; k < output.detections.size() && !beyond_floor; ++k) {
      const cv::Point2d& projector =
          sequence_.centres[pattern.array * sequence_.markers_per_array + output.detections.ids[k]];
      const cv::Point2d planned = detect::ApplyHomography(homography_.SurfaceAt(projector), projector);
      const cv::Point2d found = detect::DiagonalIntersection(output.undistorted[k]);
      const double side = MeanSide(output.detections.corners[k]);
      beyond_floor = homography_.SurfaceIndexAt(projector) != 0 ||
                     !(cv::norm(found - planned) <= detect::AllowedOffset(side, options_.roi));
    }
    // Every one of the largest scales gets its chance before the explorations space out.
    floor_only_explorations_ = beyond_floor ? 0 : floor_only_explorations_ + 1;
    const int doublings = std::min(floor_only_explorations_ - options_.explore_scales + 1, 30);
    explore_gap_ = doublings <= 0 ? options_.explore_interval
                                  : static_cast<int>(std::min<long long>(
                                        static_cast<long long>(options_.explore_interval) << doublings,
                                        options_.explore_max_interval));
  }

  // Shrinking of a whole frame searched before the homography (adaptive_bootstrap).
  int BootstrapDownscale(const PatternSpec& pattern) const {
    const int fixed = options_.bootstrap_downscale;
    const double target = options_.roi.target_module_px;
    if (!options_.adaptive_bootstrap || !options_.use_roi || target <= 0.0 || !(min_magnification_ > 0.0)) {
      return fixed;
    }
    const double module = 0.5 * min_magnification_ * pattern.marker_side_px / sequence_.markers.grid_cells;
    const int adaptive = std::min(static_cast<int>(module / target), options_.roi.max_downscale);
    return std::max(fixed, adaptive);
  }

  // The scales of pattern `index`'s array as the sequence shows them.
  detect::ScaleSelection Selection(int index) const {
    const PatternSpec& pattern = sequence_.patterns[index];
    detect::ScaleSelection selection;
    selection.current = pattern.scale_index;
    selection.max_scales = options_.max_scales_per_msm;
    selection.sides.assign(sequence_.scales.size(), 0.0);
    selection.omitted.assign(sequence_.scales.size(), {});
    for (const PatternSpec& other : sequence_.patterns) {
      if (other.array != pattern.array) continue;
      selection.sides[other.scale_index] = other.marker_side_px;
      selection.omitted[other.scale_index] = other.omitted;
    }
    return selection;
  }

  void AddFrame(int frame, const cv::Mat& gray_frame) {
    const bool first = pending_.frames.empty();
    const bool averaging = wanted_[pending_.pattern] > 1;
    if (first) KeepThumbnail(gray_frame, pending_.pattern);
    if (first) {
      pending_.job.regions.resize(pending_.rects.size());
      pending_.sums.resize(pending_.rects.size());
    }
    for (std::size_t i = 0; i < pending_.rects.size(); ++i) {
      cv::Mat gray = gray_frame(pending_.rects[i]).clone();
      if (averaging) {
        if (first) {
          gray.convertTo(pending_.sums[i], CV_16U);
        } else {
          cv::add(pending_.sums[i], gray, pending_.sums[i], cv::noArray(), CV_16U);
        }
      }
      if (first) pending_.job.regions[i] = detect::RegionImage{std::move(gray), pending_.rects[i].tl()};
    }
    pending_.frames.push_back(frame);
  }

  // A small copy of each pattern's first frame until its detections arrive: the report
  // shows the one where most markers were found (a zoomed camera may find one marker in
  // the first array and tens in another).
  void KeepThumbnail(const cv::Mat& gray_frame, int pattern) {
    if (options_.thumbnail_width <= 0 || gray_frame.empty()) return;
    const double factor = std::min(1.0, static_cast<double>(options_.thumbnail_width) / gray_frame.cols);
    const cv::Size size(std::max(1, cvRound(gray_frame.cols * factor)),
                        std::max(1, cvRound(gray_frame.rows * factor)));
    cv::resize(gray_frame, thumbnails_[pattern], size, 0.0, 0.0, cv::INTER_AREA);
  }

  void ChooseThumbnail(int pattern, int found) {
    const auto it = thumbnails_.find(pattern);
    if (it == thumbnails_.end()) return;
    if (found > thumbnail_found_) {  // ties keep the earlier pattern
      result_.thumbnail = std::move(it->second);
      result_.thumbnail_pattern = pattern;
      thumbnail_found_ = found;
    }
    thumbnails_.erase(it);
  }

  void SubmitPending() {
    PendingPattern pending = std::exchange(pending_, PendingPattern{});
    if (pending.pattern < 0 || pending.skip || pending.frames.empty()) {
      thumbnails_.erase(pending.pattern);
      return;
    }
    const int count = static_cast<int>(pending.frames.size());
    if (count > 1) {
      for (std::size_t i = 0; i < pending.sums.size(); ++i) {
        pending.sums[i].convertTo(pending.job.regions[i].gray, CV_8U, 1.0 / count);
      }
    }
    pending.job.first_frame = pending.frames.front();
    pending.job.frame_count = count;
    status_[pending.pattern] = PatternStatus::kSubmitted;
    used_frames_[pending.pattern] = pending.frames;
    ++result_.scales[sequence_.patterns[pending.pattern].scale_index].detected_patterns;
    result_.frames_detected += count;
    ++(pending.job.whole_frame ? result_.patterns_whole_frame : result_.patterns_in_regions);
    pipeline_.Submit(std::move(pending.job));
  }

  // Absorbs, in pattern order, the detections of every pattern before `pattern`
  // (waiting for them), so that what the ingest knows at any pattern is deterministic.
  void AbsorbBefore(int pattern) {
    pipeline_.WaitForPatternsBefore(pattern);
    for (DetectionOutput& output : pipeline_.Poll()) {
      const int index = output.pattern;
      arrived_.emplace(index, std::move(output));
    }
    std::vector<DetectionOutput> ready;
    while (!arrived_.empty() && arrived_.begin()->first < pattern) {
      ready.push_back(std::move(arrived_.begin()->second));
      arrived_.erase(arrived_.begin());
    }
    Absorb(ready);
  }

  // Detections -> undistorted centres (records) and homography correspondences.
  void Absorb(const std::vector<DetectionOutput>& outputs) {
    for (const DetectionOutput& output : outputs) {
      result_.seconds_detection += output.seconds;
      result_.detections_rejected += output.rejected;
      result_.markers_verified += output.verified;
      const PatternSpec& pattern = sequence_.patterns[output.pattern];
      if (output.explored && homography_.valid()) AdaptExploring(output);
      for (const detect::MarkerPrediction& marker : output.searched) {
        const auto& ids = output.detections.ids;
        const bool found = std::find(ids.begin(), ids.end(), marker.id) != ids.end();
        // A miss says the size is too small only for an MSM seen at another scale: one
        // hidden by a table, in its shadow or moved onto it is missed at every size.
        const long long key = static_cast<long long>(pattern.array) * sequence_.markers_per_array + marker.id;
        if (found || found_msms_.count(key) > 0) resolution_.Record(marker.module_px, found);
      }
      for (const int id : output.detections.ids) {
        found_msms_.insert(static_cast<long long>(pattern.array) * sequence_.markers_per_array + id);
      }
      LearnMagnification(output);
      ChooseThumbnail(output.pattern, static_cast<int>(output.detections.size()));
      for (std::size_t k = 0; k < output.detections.size(); ++k) {
        const detect::Quad& quad = output.detections.corners[k];
        const cv::Point2d centre = detect::DiagonalIntersection(output.undistorted[k]);
        if (!std::isfinite(centre.x) || !std::isfinite(centre.y)) continue;
        detect::ScaleRecord record;
        record.pattern = output.pattern;
        record.array = pattern.array;
        record.marker = output.detections.ids[k];
        record.scale_index = pattern.scale_index;
        record.corners = quad;
        record.centre = centre;
        record.side_px = MeanSide(quad);
        record.first_frame = output.first_frame;
        record.frame_count = output.frame_count;
        record.in_region = !output.whole_frame;
        result_.records.push_back(record);
        // A marker over a surface edge has a displaced centre: it would bend the fits.
        const cv::Point2d& projector = sequence_.centres[pattern.array * sequence_.markers_per_array + record.marker];
        if (!homography_.CrossesSurfaces(projector, pattern.marker_side_px)) {
          homography_.Add(projector, centre, record.side_px / (pattern.marker_side_px * sequence_.markers.quad_cells /
                                                               sequence_.markers.grid_cells));
        }
      }
    }
  }

  // The adaptive bootstrap's smallest magnification, from MSMs seen at two scales. A
  // shrunk frame that finds nothing says nothing against it: a zoomed camera's view
  // holds no whole marker of the largest scales.
  void LearnMagnification(const DetectionOutput& output) {
    const PatternSpec& pattern = sequence_.patterns[output.pattern];
    for (std::size_t k = 0; k < output.detections.size(); ++k) {
      const detect::Quad& quad = output.detections.corners[k];
      const Sighting seen{detect::DiagonalIntersection(quad), MeanSide(quad), pattern.marker_side_px};
      if (!std::isfinite(seen.centre.x) || !std::isfinite(seen.centre.y)) continue;
      const long long key = static_cast<long long>(pattern.array) * sequence_.markers_per_array +
                            output.detections.ids[k];
      const auto [first, inserted] = first_sightings_.try_emplace(key, seen);
      if (inserted || first->second.marker_side_px == seen.marker_side_px) continue;
      const Sighting& earlier = first->second;
      const double ratio = (seen.side_px / earlier.side_px) / (seen.marker_side_px / earlier.marker_side_px);
      const bool concentric =
          cv::norm(seen.centre - earlier.centre) < kConcentricShare * std::min(seen.side_px, earlier.side_px);
      if (!concentric || std::abs(ratio - 1.0) > kScaleRatioTolerance) continue;
      min_magnification_ = std::min({min_magnification_, seen.side_px / seen.marker_side_px,
                                     earlier.side_px / earlier.marker_side_px});
    }
  }

  // ------------------------------------------------------------------- finish

  void DropUncleanPatterns() {
    const sync::FrameMap& map = result_.sync.window_map;
    std::vector<bool> dropped(sequence_.patterns.size(), false);
    for (std::size_t p = 0; p < sequence_.patterns.size(); ++p) {
      if (status_[p] == PatternStatus::kNotSeen) ++result_.patterns_missing;
      if (status_[p] != PatternStatus::kSubmitted) continue;
      const PatternSpec& pattern = sequence_.patterns[p];
      for (int frame : used_frames_[p]) {
        if (!video::IsClean(map, frame, pattern.first_frame, pattern.last_frame + 1.0, options_.pick.margin)) {
          dropped[p] = true;
        }
      }
      if (dropped[p]) ++result_.patterns_dropped;
    }
    auto& records = result_.records;
    records.erase(std::remove_if(records.begin(), records.end(),
                                 [&](const detect::ScaleRecord& r) { return dropped[r.pattern]; }),
                  records.end());
  }

  // A camera whose every detected pattern was dropped has no observation, and the reason
  // is its timing, not its view: said as such rather than left to "no observations".
  void ThrowIfEveryPatternDropped() const {
    const int submitted = static_cast<int>(std::count(status_.begin(), status_.end(), PatternStatus::kSubmitted));
    if (submitted == 0 || result_.patterns_dropped < submitted) return;
    const sync::FrameMap& map = result_.sync.window_map;
    char figures[160];
    std::snprintf(figures, sizeof figures, "offset known to +-%.2f frames, exposure %.2f frames",
                  result_.sync.offset_uncertainty, map.exposure);
    throw std::runtime_error(path_ + ": every pattern's frames were dropped (" + std::to_string(submitted) +
                             " patterns): under the frame map the light codes give (" + figures +
                             ") none is clean of its neighbours; are the camera's timestamps regular?");
  }

  // Drops detections that disagree with the homographies of all the others, and those
  // over the edge between two surfaces (as the surfaces are known in the end).
  void RejectInconsistentRecords() {
    auto& records = result_.records;
    homography_.Refit();
    const auto folded = std::remove_if(records.begin(), records.end(), [&](const detect::ScaleRecord& r) {
      return homography_.CrossesSurfaces(sequence_.centres[r.array * sequence_.markers_per_array + r.marker],
                                         sequence_.patterns[r.pattern].marker_side_px);
    });
    const int crossing = static_cast<int>(records.end() - folded);
    records.erase(folded, records.end());
    std::vector<cv::Point2d> projector, image;
    std::vector<int> position;
    for (const detect::ScaleRecord& r : records) {
      projector.push_back(sequence_.centres[r.array * sequence_.markers_per_array + r.marker]);
      image.push_back(r.centre);
      position.push_back(r.marker);
    }
    const detect::ConsistencyResult check =
        detect::CheckFloorConsistency(projector, image, position, options_.consistency);
    result_.detections_inconsistent = check.rejected + crossing;
    result_.consistency_problem = check.problem;
    std::size_t next = 0;
    for (std::size_t i = 0; i < records.size(); ++i) {
      if (check.keep[i]) records[next++] = records[i];
    }
    records.resize(next);
  }

  void Summarise() {
    RejectInconsistentRecords();
    std::sort(result_.records.begin(), result_.records.end(), [](const auto& a, const auto& b) {
      return std::tie(a.array, a.marker, a.scale_index) < std::tie(b.array, b.marker, b.scale_index);
    });
    result_.centres = detect::MergeScales(&result_.records, options_.merge);
    for (const detect::ScaleRecord& r : result_.records) {
      ++result_.scales[r.scale_index].detected;
      if (r.kept) ++result_.scales[r.scale_index].kept;
    }
    MeasureSpread();
    CorrectScaleDrift();
    result_.homography_valid = homography_.valid();
    result_.homography = homography_.H();
    result_.homography_rms_px = homography_.rms_px();
  }

  // The merged centres moved for the drift of their scales on a floor that is not flat
  // (after MeasureSpread, which measures the scales' spread around their mean).
  void CorrectScaleDrift() {
    std::vector<double> side;
    for (const detect::ScaleRecord& r : result_.records) side.push_back(sequence_.patterns[r.pattern].marker_side_px);
    std::vector<cv::Point2d> projector;
    for (const detect::MergedCentre& c : result_.centres) {
      projector.push_back(sequence_.centres[c.array * sequence_.markers_per_array + c.marker]);
    }
    result_.scale_drift =
        detect::CorrectScaleDrift(result_.records, side, projector, &result_.centres, options_.scale_drift);
  }

  // Per scale, how far its kept detections lie from their MSM's merged centre (records
  // and centres are both sorted by array and marker).
  void MeasureSpread() {
    std::vector<double> squares(result_.scales.size(), 0.0);
    const auto& records = result_.records;
    std::size_t next = 0;
    for (const detect::MergedCentre& centre : result_.centres) {
      const auto msm = std::tie(centre.array, centre.marker);
      while (next < records.size() && std::tie(records[next].array, records[next].marker) < msm) ++next;
      for (std::size_t k = next; k < records.size() && std::tie(records[k].array, records[k].marker) == msm; ++k) {
        const detect::ScaleRecord& r = records[k];
        if (!r.kept || centre.scales_kept < 2) continue;
        const cv::Point2d d = r.centre - centre.centre;
        squares[r.scale_index] += d.dot(d);
        ++result_.scales[r.scale_index].spread_count;
      }
    }
    for (std::size_t s = 0; s < squares.size(); ++s) {
      ScaleStats& stats = result_.scales[s];
      if (stats.spread_count > 0) stats.spread_px = std::sqrt(squares[s] / stats.spread_count);
    }
  }

  std::string path_;
  const SequenceDescription& sequence_;
  formats::CameraIntrinsics camera_;
  std::string intrinsics_source_;
  video::VideoReader reader_;
  IngestOptions options_;
  ProgressCallback progress_;
  detect::MarkerFamily family_;
  sync::LightTimeline timeline_;
  double nominal_rate_;
  std::unique_ptr<sync::CodeTracker> tracker_;
  video::LumaMeter luma_;
  video::FrameRing ring_;
  video::FrameClock clock_;
  std::vector<double> band_means_;                // scratch: band means of one frame
  std::vector<std::vector<double>> band_signals_; // mean luma per band and grid slot
  int last_search_ = std::numeric_limits<int>::min() / 2;
  detect::ProjectorHomography homography_;
  detect::ResolutionLimit resolution_;
  std::unordered_set<long long> found_msms_;  // array * markers_per_array + marker, at any scale
  // Exploring: arrays from one explored to the next (at least explore_interval), the last
  // explored, how many so far, and how many in a row found nothing beyond the floor.
  int explore_gap_ = 0;
  int floor_only_explorations_ = 0;
  int last_explored_array_ = std::numeric_limits<int>::min() / 2;
  int explorations_ = 0;
  // Smallest image side over projector side of the MSMs found at two scales so far.
  double min_magnification_ = std::numeric_limits<double>::infinity();
  struct Sighting {
    cv::Point2d centre;   // distorted pixels
    double side_px;
    double marker_side_px;  // the pattern's, in projector pixels
  };
  std::unordered_map<long long, Sighting> first_sightings_;  // array * markers_per_array + marker
  DetectionPipeline pipeline_;

  bool started_ = false;
  bool converted_ = false;
  sync::CodeLocation start_;
  sync::FrameMap provisional_;
  std::vector<std::vector<int>> picks_;  // candidate frames per pattern, increasing
  std::vector<int> wanted_;              // frames averaged per pattern
  std::map<int, int> frame_pattern_;
  int end_means_first_ = 0;
  int end_means_last_ = -1;
  int last_needed_frame_ = -1;  // the last camera frame the sync or a pick uses
  PendingPattern pending_;
  std::map<int, DetectionOutput> arrived_;  // finished, not yet absorbed, by pattern
  std::map<int, cv::Mat> thumbnails_;       // submitted patterns' first frames, small
  int thumbnail_found_ = -1;                // markers found in the pattern of result_.thumbnail
  std::vector<PatternStatus> status_;
  std::vector<std::vector<int>> used_frames_;
  CameraIngestResult result_;
};

}  // namespace

bool ValidKnownExposure(double seconds) { return seconds > 0.0 && seconds <= kMaxExposureS; }

IngestOptions OptionsForUnrefinedLenses() {
  IngestOptions options;
  options.consistency.local_neighbours = 0;
  options.scale_drift.enabled = false;
  return options;
}

void IngestOptions::Check() const {
  sync.Check();
  pick.Check();
  detector.aruco.Check();
  detector.apriltag.Check();
  roi.Check();
  homography.Check();
  merge.Check();
  scale_drift.Check();
  Require(mean_row_step >= 1 && mean_row_step <= limits::kMaxImageSide,
          "mean_row_step must be in [1, " + std::to_string(limits::kMaxImageSide) + "]");
  Require(luma_gamma > 0.0, "luma_gamma must be positive");
  Require(exposure_s == 0.0 || ValidKnownExposure(exposure_s),
          "exposure_s must be 0 (estimate it) or a time of at most 1 s");
  Require(readout_bands == 0 || (readout_bands >= 3 && readout_bands <= 64),
          "readout_bands must be 0 or in [3, 64]");
  Require(readout_sigmas > 0.0, "readout_sigmas must be positive");
  Require(max_readout_sigma > 0.0, "max_readout_sigma must be positive");
  Require(unmeasured_readout_frames >= 0.0 && unmeasured_readout_frames <= 1.0,
          "unmeasured_readout_frames must be in [0, 1] (a readout longer than a frame leaves no time to expose)");
  Require(max_frame_gap_s > 0.0 && std::isfinite(max_frame_gap_s), "max_frame_gap_s must be positive");
  // Frames held in memory: the lookback and the pending jobs.
  Require(lookback_frames >= 0 && lookback_frames <= kMaxHeldFrames,
          "lookback_frames must be in [0, " + std::to_string(kMaxHeldFrames) + "]");
  Require(search_interval >= 1, "search_interval must be at least 1");
  Require(decode_threads >= 0 && decode_threads <= limits::kMaxThreads,
          "decode_threads must be in [0, " + std::to_string(limits::kMaxThreads) + "]");
  Require(detection_threads >= 1 && detection_threads <= limits::kMaxThreads,
          "detection_threads must be in [1, " + std::to_string(limits::kMaxThreads) + "]");
  Require(max_pending_jobs >= 1 && max_pending_jobs <= kMaxHeldFrames,
          "max_pending_jobs must be in [1, " + std::to_string(kMaxHeldFrames) + "]");
  Require(planning_lag >= 0, "planning_lag must be non-negative");
  Require(thumbnail_width >= 0 && thumbnail_width <= 4096, "thumbnail_width must be in [0, 4096]");
  Require(max_scales_per_msm >= 0, "max_scales_per_msm must be non-negative (0: every scale)");
  Require(bootstrap_downscale >= 1 && bootstrap_downscale <= 8, "bootstrap_downscale must be in [1, 8]");
  Require(explore_interval >= 0, "explore_interval must be non-negative (0: never)");
  Require(explore_scales >= 1, "explore_scales must be at least 1");
  Require(explore_max_interval >= 1, "explore_max_interval must be at least 1");
  edges.Check();
  verification.Check();
  consistency.Check();
  Require(edge_gap_share > 0.0 && edge_gap_share <= 1.0, "edge_gap_share must be in (0, 1]");
  VisitIngestOptions(*this, limits::OptionChecker{"ingest options: "});
}

int SharedDecodeThreads(int decode_threads, int cameras_at_once) {
  if (decode_threads != 0) return decode_threads;  // a bad value stays for Check
  const int cores = static_cast<int>(std::max(1U, std::thread::hardware_concurrency()));
  // A camera alone leaves a core to its detection thread.
  if (cameras_at_once <= 1) return std::max(1, cores - 1);
  return std::max(1, cores / cameras_at_once);
}

CameraIngestResult IngestCamera(const std::string& video_path, const SequenceDescription& sequence,
                                const formats::CameraIntrinsics& camera, const std::string& intrinsics_source,
                                const IngestOptions& options, const ProgressCallback& progress,
                                const video::SourceOptions& source) {
  detect::CheckLens(camera);
  sequence.Check();
  options.Check();
  return CameraIngest(video_path, sequence, camera, intrinsics_source, options, progress, source).Run();
}

}  // namespace calibproj::ingest
