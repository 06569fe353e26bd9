#pragma once
// From one camera's video to the image positions of the MSM centres it saw.
//
// One decoding pass: every frame is decoded once; its mean luma is measured until the
// start light code is found (incrementally, code_search.h) and around where the end
// code must be. From the start code on, the frames that show each pattern cleanly are
// known, so only those are converted and handed (whole, or as regions of interest
// once the projector-to-image homography is known) to detection threads while
// decoding goes on. After the last frame both codes give the final frame map; a pattern
// whose frames turn out not to be clean under it is dropped. The detections of every
// MSM over its scales are undistorted and merged (msm_merge.h).

#include <functional>
#include <string>
#include <vector>

#include "calibproj/detect/floor_consistency.h"
#include "calibproj/detect/lens.h"
#include "calibproj/detect/marker_detector.h"
#include "calibproj/detect/marker_verification.h"
#include "calibproj/detect/msm_merge.h"
#include "calibproj/detect/scale_drift.h"
#include "calibproj/detect/projector_homography.h"
#include "calibproj/detect/resolution_limit.h"
#include "calibproj/detect/roi.h"
#include "calibproj/detect/undistorted_edges.h"
#include "calibproj/ingest/sequence_description.h"
#include "calibproj/sync/synchronise.h"
#include "calibproj/video/frame_clock.h"
#include "calibproj/video/frame_picker.h"
#include "calibproj/video/video_reader.h"

namespace calibproj::ingest {

struct IngestOptions {
  sync::SyncOptions sync;
  video::PickOptions pick;
  detect::DetectorOptions detector;  // `inverted` is taken from the sequence
  detect::RoiOptions roi;
  detect::HomographyOptions homography;
  // Scales searched per MSM at most: a marker is left out when this many larger scales
  // of its MSM are worth searching (0: every scale).
  int max_scales_per_msm = 4;
  // Stop searching markers of sizes this camera has not been decoding.
  bool learn_resolution = true;
  detect::ResolutionOptions resolution;
  detect::MergeOptions merge;
  // Merged centres moved to where a marker of no size would put them (scale_drift.h).
  detect::ScaleDriftOptions scale_drift;
  // Every detection checked against one homography of the floor (wrong ids, frames of
  // another pattern).
  detect::ConsistencyOptions consistency;
  // Detect in regions of interest once the homography is known (false: whole frames
  // at full resolution, with the same filtering; for verification).
  bool use_roi = true;
  // One scale of an array every explore_interval arrays is searched in the whole frame
  // (shrunk as its markers allow) and its markers kept wherever they are found: markers
  // moved by a surface whose homography is not known yet (a table top) are found there,
  // and that surface's homography then plans the later patterns (0: never). The explored
  // arrays take the explore_scales largest scales in turn. Whole frames cost far more
  // than regions: after explore_scales explorations in a row whose markers all lie on the
  // floor where it plans them, each further one doubles the interval, up to
  // explore_max_interval arrays; one marker on another surface or off the plan brings it
  // back.
  int explore_interval = 1;
  int explore_max_interval = 8;
  int explore_scales = 3;
  // Whole frames searched before the homography is known are shrunk by this factor
  // (libapriltag takes ~300 ms on a full 1080p frame); markers too small to survive
  // the shrinking are then only found once regions of interest take over.
  int bootstrap_downscale = 1;
  // With regions of interest, whole frames before the homography are shrunk further as
  // far as the markers found so far allow: the next pattern's module, predicted at half
  // the smallest magnification (image over projector pixels) seen, is brought near
  // roi.target_module_px (at most roi.max_downscale). A zoomed camera that needs many
  // patterns before its homography then does not pay full frames for them.
  bool adaptive_bootstrap = true;
  // Corners from straight edge lines fitted in undistorted pixels (undistorted_edges.h),
  // starting from the detector's unrefined corners; false: the detector's own corner
  // refinement, then cv::undistortPoints of the four corners.
  bool refine_undistorted = true;
  detect::UndistortedEdgeOptions edges;
  // With refine_undistorted, a marker planned in a region is first looked for at its
  // predicted corners: the edge fit starts there and the expected id's cells are read
  // through the fitted corners (marker_verification.h); the detector searches only the
  // regions where that fails. false: the detector searches every region.
  bool verify_predicted = true;
  detect::VerificationOptions verification;
  // Edge profiles reach out of a marker at most this share of the gap to the next
  // marker of its pattern (and at most edges.outward_fraction of a module).
  double edge_gap_share = 0.4;
  // Known exposure time of the camera in seconds, or 0 to estimate it from the codes
  // (see CodeFitOptions::fixed_exposure).
  double exposure_s = 0.0;
  // Mean luma over every mean_row_step-th row, linearised by luma_gamma (the video's
  // display gamma; 1 = use the encoded values).
  int mean_row_step = 2;
  double luma_gamma = 2.2;
  // Time from the container's frame timestamps (frames placed on the frame grid, so
  // dropped frames leave gaps instead of shifting every later frame); false: from the
  // decoding order, for containers whose timestamps are wrong.
  bool use_timestamps = true;
  // Largest gap between consecutive frames' timestamps, seconds, before the video is
  // rejected (a paused recording or a corrupt timestamp).
  double max_frame_gap_s = 2.0;
  // Horizontal bands of the image whose light codes give the rolling-shutter readout
  // (0: not measured); a readout beyond readout_sigmas standard deviations and known
  // to max_readout_sigma camera frames moves the frame map to the first row and widens
  // the frames' windows to every row.
  int readout_bands = 16;
  double readout_sigmas = 3.0;
  double max_readout_sigma = 0.1;
  // A readout that could not be measured (no band sees a light change) may be anything
  // up to this many camera frames: the offset, which then refers to the rows that see
  // the projection, has its uncertainty widened by the share of it that lies between
  // those rows and the farther of the first and last rows (half of it when the
  // projection fills the image; 0 assumes a global shutter).
  double unmeasured_readout_frames = 1.0;
  // Decoded grey frames kept while the start code is being looked for.
  int lookback_frames = 16;
  // Frames decoded between two incremental searches of the start code.
  int search_interval = 4;
  // FFmpeg's decoding threads per camera; 0: the machine's cores shared among the
  // cameras ingested at once (SharedDecodeThreads), all but one for a camera alone.
  int decode_threads = 0;
  int detection_threads = 1;
  int max_pending_jobs = 4;
  // The homography and the resolution limit used to plan a pattern come from the
  // detections of the patterns at least this many before it, whatever the threads'
  // timing: results do not depend on how fast detection keeps up.
  int planning_lag = 4;
  // A grey copy of the frame where most markers were found, this many pixels wide, for the
  // report to draw detections on (0: none).
  int thumbnail_width = 640;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

// The ingest options of a calibration that refines lenses when none are given: the
// local consistency check off, as it compares each centre with its neighbours to a
// fraction of a pixel, which a lens still to be refined does not allow; and the scale
// drift off, as such a lens bends a large marker's corners and its scales disagree by
// the lens's error, not the floor's.
IngestOptions OptionsForUnrefinedLenses();

// A camera's known exposure time (--exposure CAMERA=SECONDS): more than 0 and at most
// kMaxExposureS (no video camera exposes a frame longer; one longer than its frame is
// taken as the whole frame). The one check of both tools' command lines.
constexpr double kMaxExposureS = 1.0;
bool ValidKnownExposure(double seconds);

// What happened to the patterns of one scale.
struct ScaleStats {
  int patterns = 0;          // patterns of this scale in the sequence
  int detected_patterns = 0; // patterns whose frames went to detection
  int skipped_patterns = 0;  // no marker resolvable or inside the image
  int searched = 0;          // markers searched (planned, or all on whole frames)
  int too_small = 0;
  int outside = 0;
  int folded = 0;            // over the edge between two surfaces (a table's)
  int unresolvable = 0;      // of a size the camera was not decoding
  int redundant = 0;         // left to larger scales of their MSM
  int detected = 0;          // markers found
  int kept = 0;              // used in merged centres
  // Repeatability of the centres: RMS distance (undistorted px) of the kept detections
  // of this scale from their MSM's merged centre, over MSMs kept at two scales or more;
  // spread_count such detections (0: none, and spread_px means nothing).
  double spread_px = 0.0;
  int spread_count = 0;
};

struct CameraIngestResult {
  video::VideoInfo video;
  sync::SyncResult sync;
  // Frames on the frame grid: dropped and duplicated frames, timing jitter. Frame
  // numbers everywhere (signal, sync, records) are grid slots.
  video::FrameClockStats timing;
  int frames_decoded = 0;
  int frames_converted = 0;    // decoded frames whose grey image was made (to detect on)
  int frames_detected = 0;     // frames that went into a detection
  int patterns_whole_frame = 0;
  int patterns_in_regions = 0;
  int patterns_dropped = 0;    // frames not clean under the final frame map
  int patterns_missing = 0;    // not recorded (before the video starts or after it ends)
  int detections_rejected = 0; // unexpected id, duplicate, or off the prediction
  int markers_verified = 0;    // found at their predicted corners, without the detector
  int detections_inconsistent = 0;  // off the homographies of the others, or over a surface edge
  std::string consistency_problem;  // set when no detection could be trusted
  std::vector<ScaleStats> scales;
  std::vector<detect::ScaleRecord> records;
  std::vector<detect::MergedCentre> centres;
  detect::ScaleDriftResult scale_drift;  // how the centres were moved for their scales' drift
  std::vector<double> signal;  // mean luma per grid slot, NaN where not measured or dropped
  std::vector<std::vector<double>> band_signals;  // the same per band of rows (readout)
  bool homography_valid = false;
  cv::Matx33d homography = cv::Matx33d::eye();  // projector pixels -> undistorted pixels
  double homography_rms_px = 0.0;
  double seconds_total = 0.0;
  double seconds_detection = 0.0;  // CPU time of the detection threads
  cv::Mat thumbnail;               // CV_8U, empty when thumbnail_width is 0
  int thumbnail_pattern = -1;      // the pattern the thumbnail shows
};

// Called now and then with the frames decoded so far and the declared total.
using ProgressCallback = std::function<void(int decoded, int total)>;

// Ingests one camera. Throws std::runtime_error / std::invalid_argument naming the
// video (or the intrinsics source) when the video cannot be read, has another frame
// size than the intrinsics, or cannot be synchronised with the sequence.
// With a live `source` (a stream or device, video_reader.h) the camera is ingested as
// its frames arrive (and recorded, when the source says where): the ingest ends
// once the frames of the end light code are in, and a source that stalls or is
// stopped before then fails with the reason.
// `camera`'s image size, when it has one, is the frame size expected; `intrinsics_source`
// names where its intrinsics come from, for messages.
CameraIngestResult IngestCamera(const std::string& video_path, const SequenceDescription& sequence,
                                const formats::CameraIntrinsics& camera, const std::string& intrinsics_source,
                                const IngestOptions& options, const ProgressCallback& progress = {},
                                const video::SourceOptions& source = {});

// The decoding threads each of `cameras_at_once` cameras ingested together gets:
// `decode_threads` when it is set, else the machine's cores shared among them (at least
// one each; all but one, left to its detection thread, for a camera alone). FFmpeg's
// frame threads cost CPU to keep in step, so cameras decoded side by side on one thread
// each do the same work in less time than each on every core (measured on the demo
// room's six cameras ingested one by one on 2 cores: 9 % less CPU on one thread than with
// FFmpeg's own choice, 14 % more wall time).
int SharedDecodeThreads(int decode_threads, int cameras_at_once);

}  // namespace calibproj::ingest
