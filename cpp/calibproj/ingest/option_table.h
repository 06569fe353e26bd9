#pragma once
// Every knob of the ingest, by name, in one table: the Python binding (keyword
// options, calibproj.ingest.options.IngestOptions) and the standalone executable
// (command-line flags) both walk it, so neither can miss a knob.
//
// visit(name, field, help) is called once per knob, in the order of IngestOptions'
// documentation; `name` is snake_case (flags use dashes).

#include "calibproj/ingest/camera_ingest.h"

namespace calibproj::ingest {

// The synchronisation knobs shared with the bare sync (calibproj._core.sync).
template <typename SyncOptionsT, typename Visitor>
void VisitSyncOptions(SyncOptionsT& s, Visitor&& visit) {
  visit("min_correlation", s.min_correlation,
        "normalised cross-correlation a light code must reach.");
  visit("max_rate_deviation", s.max_rate_deviation,
        "largest relative difference between the rate the two codes give and the video's nominal rate "
        "before they count as disagreeing.");
  visit("context_before", s.context_before,
        "projector frames of known light (reference frames) used before each code.");
  visit("context_after", s.context_after,
        "projector frames of known light used after each code.");
  visit("guard_samples", s.guard_samples,
        "camera frames searched past the best start-code match before it is accepted while decoding.");
  visit("rate_search", s.search.rate_search,
        "candidate rates span the nominal rate x (1 +- rate_search).");
  visit("rate_step", s.search.rate_step,
        "relative step between candidate rates.");
  visit("phases", s.search.phases,
        "sub-frame phases per candidate rate in the coarse search.");
  visit("coarse_exposure", s.search.exposure,
        "exposure assumed by the coarse search, camera frames.");
  visit("max_missing_share", s.search.max_missing_share,
        "share of a light code's camera frames that may be missing (dropped by the camera) where the code "
        "is searched; the correlation is taken over the frames present.");
  visit("detrend_frames", s.search.detrend_frames,
        "the code search compares signal and code after subtracting their mean over +- this many camera "
        "frames (0: not at all), so that a camera whose automatic exposure settles while the code plays "
        "still finds it.");
  visit("offset_range", s.fit.offset_range,
        "the sub-frame fit searches +- this many camera frames around the coarse offset.");
  visit("offset_step", s.fit.offset_step,
        "grid step of the sub-frame fit, camera frames.");
  visit("min_exposure", s.fit.min_exposure,
        "shortest exposure the fit tries, camera frames.");
  visit("max_exposure", s.fit.max_exposure,
        "longest exposure the fit tries, camera frames.");
  visit("exposure_steps", s.fit.exposure_steps,
        "exposures the fit tries between the two.");
  visit("feasible_chi2", s.fit.feasible_chi2,
        "a frame map fits as well as the best when its cost exceeds the best by less than this many "
        "residual variances per frame; the offsets of those maps give the reported uncertainty and the "
        "exposure windows that count for picking clean frames.");
  visit("plateau_tolerance", s.fit.plateau_tolerance,
        "a frame map also fits as well when its cost exceeds the best by less than this share of the "
        "signal's variance (noise-free plateaus).");
  visit("fit_iterations", s.fit.max_iterations,
        "Levenberg-Marquardt iterations of the fit.");
  visit("gain_drift", s.fit.gain_drift,
        "the black level and contrast of each code window drift linearly in time (a camera adjusting its "
        "exposure or gain during the code); false keeps them constant per window.");
}

template <typename IngestOptionsT, typename Visitor>
void VisitIngestOptions(IngestOptionsT& o, Visitor&& visit) {
  VisitSyncOptions(o.sync, visit);
  visit("exposure_s", o.exposure_s,
        "known exposure time of the cameras, seconds, or 0 to estimate it from the codes. Where every "
        "light change falls at the same phase of a camera's frames (camera at the projector's rate or a "
        "multiple of it), a frame across a change only tells how its exposure splits, and the offset is "
        "known exactly only with the exposure.");
  visit("margin", o.pick.margin,
        "projector frames kept clear of each pattern change, on either side.");
  visit("average_frames", o.pick.average_frames,
        "clean frames averaged per pattern before detection (the most central ones; fewer where the "
        "camera records fewer). Three lower the sensor and compression noise that limits the centres "
        "under strong room light, but have been seen to cost a 60 fps camera on a strongly textured floor "
        "its markers; one is the default.");
  visit("spare_frames", o.pick.spare_frames,
        "further clean frames per pattern, after the first picked one, that stand in for picked frames "
        "the camera dropped.");
  visit("max_clock_drift", o.pick.max_clock_drift,
        "largest relative camera clock drift; widens the frames kept clear while decoding, before the end "
        "code is seen.");
  visit("use_roi", o.use_roi,
        "detect in predicted regions once the projector-to-image homography is known (false: whole frames "
        "at full resolution, for verification).");
  visit("explore_interval", o.explore_interval,
        "one scale of an array every n arrays is searched in whole frames for markers on other surfaces "
        "(0: never).");
  visit("explore_max_interval", o.explore_max_interval,
        "... after explore_scales explorations in a row whose markers all lie on the floor where it plans "
        "them, each further one doubles that interval, up to this many arrays; a marker on another "
        "surface or off the plan brings it back.");
  visit("explore_scales", o.explore_scales,
        "the explored arrays take this many of the largest scales in turn: the largest are found from "
        "afar, smaller ones fit on a narrow table.");
  visit("bootstrap_downscale", o.bootstrap_downscale,
        "whole frames searched before the homography is known are shrunk by this factor (libapriltag "
        "takes ~300 ms on a full 1080p frame); markers too small to survive it are found once regions "
        "take over.");
  visit("adaptive_bootstrap", o.adaptive_bootstrap,
        "with use_roi, those whole frames are shrunk further as far as the markers found so far allow "
        "(the next pattern's module, predicted at half the smallest magnification of an MSM seen at two "
        "of its scales, near target_module_px; a marking that decodes cannot teach it): a zoomed camera "
        "that needs many patterns before its homography does not pay full frames for them.");
  visit("refine_undistorted", o.refine_undistorted,
        "corners from straight edge lines fitted in undistorted pixels, starting from the detector's "
        "unrefined corners (false: the detector's own refinement, then the four corners undistorted); "
        "straight edges of large markers bend under lens distortion.");
  visit("verify_predicted", o.verify_predicted,
        "with refine_undistorted, a marker planned in a region is first looked for at its predicted "
        "corners (edge fit from there, then the expected id's cells read through the fitted corners); "
        "the detector searches only where that fails (false: the detector searches every region).");
  visit("verify_min_contrast", o.verification.min_contrast,
        "grey levels at least between the mean white and black cells of a marker looked for at its "
        "prediction; every cell must lie on its side of their middle.");
  visit("verify_samples", o.verification.samples,
        "each cell is read as the mean of this many by this many points ...");
  visit("verify_cell_share", o.verification.cell_share,
        "... spread over this middle share of its side.");
  visit("edge_search_fraction", o.edges.search_fraction,
        "how far each intensity profile across an edge reaches into the marker, as a share of one module.");
  visit("edge_outward_fraction", o.edges.outward_fraction,
        "how far it reaches out of the marker, at most (share of a module).");
  visit("edge_gap_share", o.edge_gap_share,
        "... and at most this share of the gap to the next marker of the pattern (markers may be only "
        "half a module apart at the largest scale).");
  visit("edge_spacing_px", o.edges.spacing_px,
        "one profile every this many pixels along each edge.");
  visit("edge_min_samples", o.edges.min_samples,
        "profiles per edge at least.");
  visit("edge_max_samples", o.edges.max_samples,
        "profiles per edge at most (large markers gain nothing from more).");
  visit("edge_profile_samples_per_px", o.edges.profile_samples_per_px,
        "samples along a profile per pixel.");
  visit("edge_max_profile_samples", o.edges.max_profile_samples,
        "samples along a profile at most.");
  visit("edge_end_margin", o.edges.end_margin,
        "share of each edge left out at either end.");
  visit("edge_min_contrast", o.edges.min_contrast,
        "profiles with less contrast than this share of their edge's median are ignored.");
  visit("edge_passes", o.edges.passes,
        "edge fits at most, each from the previous result (profiles centre on their edges over the "
        "passes).");
  visit("edge_tolerance_px", o.edges.tolerance_px,
        "... stopping once no corner moves, or is predicted to move at the next pass (the moves shrink "
        "geometrically), by more than this.");
  visit("roi_padding_fraction", o.roi.padding_fraction,
        "padding around a predicted marker, as a share of its side (the larger of this and "
        "roi_padding_px).");
  visit("roi_padding_px", o.roi.padding_px,
        "padding around a predicted marker, pixels.");
  visit("roi_alignment", o.roi.alignment,
        "regions start on multiples of this many pixels.");
  visit("min_module_px", o.roi.min_module_px,
        "markers whose predicted cell is smaller are not searched.");
  visit("border_px", o.roi.border_px,
        "a marker must lie this far inside the image to be searched.");
  visit("max_roi_area_fraction", o.roi.max_area_fraction,
        "when the regions' pixels exceed this share of the frame's (both as searched, after shrinking), "
        "one whole-frame detection replaces them.");
  visit("max_offset_px", o.roi.max_offset_px,
        "a detection must lie within the larger of this and max_offset_fraction of its side from its "
        "prediction, pixels.");
  visit("max_offset_fraction", o.roi.max_offset_fraction,
        "see max_offset_px.");
  visit("target_module_px", o.roi.target_module_px,
        "a marker whose predicted module exceeds this is detected in its region shrunk by an integer "
        "factor bringing the module near this size (its corners are refined at full resolution anyway); 0 "
        "= never shrink.");
  visit("max_downscale", o.roi.max_downscale,
        "largest such factor.");
  visit("roi_threshold_window_px", o.roi.threshold_window_px,
        "ArUco's adaptive threshold window in regions, pixels: the marker's size there is known, so one "
        "window does where a whole frame needs several (about 1.5x faster detection on the mock OR); 0 "
        "keeps the detector's own.");
  visit("roi_min_white_black_diff", o.roi.min_white_black_diff,
        "libapriltag's minimum white-black contrast in regions, grey levels: flat noisy background below "
        "it is not segmented (about 1.6x faster detection on the mock OR); 0 keeps the detector's own.");
  visit("max_scales_per_msm", o.max_scales_per_msm,
        "scales searched per MSM at most: a marker is left out when this many larger scales of its MSM "
        "are worth searching (larger markers give better centres); 0 searches every scale.");
  visit("learn_resolution", o.learn_resolution,
        "stop searching markers of sizes the camera has not been decoding (judged per bin of predicted "
        "module size).");
  visit("resolution_bin_px", o.resolution.bin_px,
        "width of those bins, pixels of module size.");
  visit("resolution_min_trials", o.resolution.min_trials,
        "markers searched in a bin before it is judged.");
  visit("resolution_min_found_share", o.resolution.min_found_share,
        "a bin (and every smaller size) is given up below this share found.");
  visit("homography_min_points", o.homography.min_points,
        "distinct MSM centres needed before the homography is trusted.");
  visit("homography_min_spread", o.homography.min_spread,
        "those centres must spread over this share of the image diagonal.");
  visit("homography_threshold_px", o.homography.ransac_threshold_px,
        "RANSAC inlier threshold of the homography fit.");
  visit("homography_min_inlier_share", o.homography.min_inlier_share,
        "share of inliers the fit needs.");
  visit("homography_max_rms_px", o.homography.max_rms_px,
        "inlier RMS the fit must stay under.");
  visit("homography_max_scale_ratio", o.homography.max_scale_ratio,
        "a fit whose scale at its points differs from the markers' own (image side over projector side, "
        "median over the points) by more than this factor either way is not taken: MSMs found along one "
        "line fit degenerate homographies exactly.");
  visit("consistency_px", o.consistency.threshold_px,
        "every detection is checked against one homography of the floor (RANSAC over all of the camera's "
        "detections); those farther than this from its prediction (a wrong id, a frame of another "
        "pattern) are dropped.");
  visit("consistency_min_share", o.consistency.min_share,
        "when fewer than this share of the detections agree on one homography, none of them is kept.");
  visit("consistency_min_positions", o.consistency.min_positions,
        "marker positions the agreeing detections must cover, else all are dropped");
  visit("consistency_max_surfaces", o.consistency.max_surfaces,
        "surfaces whose detections are kept, one homography each: the floor, then among the detections "
        "left the largest group that agrees on another homography (a table top, a cart left in the "
        "projection), if it has enough detections at enough places. The same surfaces plan the regions "
        "searched: each marker where the surface its projector centre lands on puts it.");
  visit("consistency_local_neighbours", o.consistency.local_neighbours,
        "the threshold above leaves room for lenses known only roughly, whose residuals vary slowly over "
        "the image; a marker partly hidden by a table or cut by its shadow decodes with its centre a "
        "pixel or two off and stands out against its neighbours: each detection's residual is compared "
        "with the median residual of this many nearest detections of other markers on its surface (0: no "
        "such check).");
  visit("consistency_local_sigmas", o.consistency.local_sigmas,
        "... and dropped when the difference exceeds this many robust standard deviations of all such "
        "differences,");
  visit("consistency_min_local_px", o.consistency.min_local_px,
        "... and this many pixels.");
  visit("max_deviation_px", o.merge.max_deviation_px,
        "scales of an MSM farther than this from their median are rejected.");
  visit("min_scales", o.merge.min_scales,
        "scales an MSM needs (after rejection) to give a centre.");
  visit("scale_drift", o.scale_drift.enabled,
        "on a floor that is not flat a marker's corners leave its plane, and its centre drifts with the "
        "square of its size (0.1 px on a floor 6 mm uneven): the drift is measured from the scales of "
        "each MSM, smoothly over the floor, and every merged centre moved to where a marker of no size "
        "would put it, when it predicts the scales' disagreement (cross-validated).");
  visit("scale_drift_min_msms", o.scale_drift.min_msms,
        "... provided this many MSMs are kept at two scales of different sizes (with fewer, noise "
        "passes for a drift: 8 MSMs of a camera's small markers \"predicted\" 29 % of their "
        "disagreement on a rendered room);");
  visit("scale_drift_prior_msms", o.scale_drift.prior_msms,
        "... and the drift is shrunk towards none as if this many MSMs had measured none at every place "
        "(a centre with few such neighbours is moved by less);");
  visit("scale_drift_min_gain", o.scale_drift.min_gain,
        "... and a drift is used only when it predicts this share of the scales' disagreement, each MSM's "
        "from the others' (on a flat floor noise alone predicts a few percent).");
  visit("readout_bands", o.readout_bands,
        "horizontal bands of the image whose light codes are fitted separately: their offsets give a "
        "rolling shutter's readout time (0: not measured).");
  visit("readout_sigmas", o.readout_sigmas,
        "a readout beyond this many standard deviations moves the frame map to the first row (the frame's "
        "timestamp) and widens each frame's window to every row's exposure, so that a picked frame shows "
        "one pattern in all its rows.");
  visit("max_readout_sigma", o.max_readout_sigma,
        "... provided it is known to this many camera frames (1 sigma); a readout known less well is "
        "reported, not used; the offset, which then refers to the rows that see the projection, has its "
        "uncertainty widened by the readout (plus two sigma) times the share of the image between those "
        "rows and the farther of the first and last rows (half when the projection fills the image).");
  visit("unmeasured_readout_frames", o.unmeasured_readout_frames,
        "the readout of a camera where it cannot be measured (no band of rows sees a light change) may be "
        "anything up to this many camera frames: its offset's uncertainty widens by that share of it (0 "
        "assumes a global shutter; 1, the default, any rolling shutter).");
  visit("use_timestamps", o.use_timestamps,
        "time comes from the container's frame timestamps: each frame is placed on the camera's frame "
        "grid, so dropped frames leave gaps instead of shifting every later frame (false: time from the "
        "decoding order, for containers whose timestamps are wrong).");
  visit("max_frame_gap_s", o.max_frame_gap_s,
        "a gap longer than this between consecutive frames' timestamps (a paused recording, a corrupt "
        "timestamp) fails the camera.");
  visit("mean_row_step", o.mean_row_step,
        "the mean luma is taken over every n-th row.");
  visit("luma_gamma", o.luma_gamma,
        "the video's display gamma, undone per pixel before the mean, so that a frame across a light "
        "change measures the exposure-weighted mean (1 keeps the encoded values).");
  visit("lookback_frames", o.lookback_frames,
        "decoded frames kept while the start code is searched.");
  visit("search_interval", o.search_interval,
        "frames between two searches of the start code.");
  visit("decode_threads", o.decode_threads,
        "FFmpeg's decoding threads per camera (0: the machine's cores shared among the cameras ingested "
        "at once, one each when there are as many cameras as cores, all but one for a camera alone).");
  visit("detection_threads", o.detection_threads,
        "detection threads per camera.");
  visit("max_pending_jobs", o.max_pending_jobs,
        "patterns waiting for detection at most (bounds memory).");
  visit("planning_lag", o.planning_lag,
        "a pattern's regions are planned from the detections of the patterns at least this many before "
        "it, whatever the threads' timing, so that results do not depend on how fast detection keeps up.");
  visit("thumbnail_width", o.thumbnail_width,
        "width in pixels of the grey copy of a frame, which the report draws the camera's detections on: "
        "the first frame of the pattern where most markers were found (0: none).");
}

}  // namespace calibproj::ingest
