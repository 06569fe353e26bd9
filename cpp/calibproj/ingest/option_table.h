#pragma once
// Every knob of the ingest, by name, in one table: the Python binding (keyword
// options, calibproj.ingest_options.IngestOptions) and the standalone executable
// (command-line flags) both walk it, so neither can miss a knob.
//
// visit(name, field, help) is called once per knob, in the order of IngestOptions'
// documentation; `name` is snake_case (flags use dashes).

#include "calibproj/ingest/camera_ingest.h"

namespace calibproj::ingest {

// The synchronisation knobs shared with the bare sync (calibproj._core.sync).
template <typename SyncOptionsT, typename Visitor>
void VisitSyncOptions(SyncOptionsT& s, Visitor&& visit) {
  visit("min_correlation", s.min_correlation, "normalised cross-correlation a light code must reach");
  visit("max_rate_deviation", s.max_rate_deviation, "largest relative rate difference between codes and video");
  visit("context_before", s.context_before, "projector frames of known light used before each code");
  visit("context_after", s.context_after, "projector frames of known light used after each code");
  visit("guard_samples", s.guard_samples, "camera frames searched past the best start-code match");
  visit("rate_search", s.search.rate_search, "candidate rates span the nominal rate x (1 +- rate_search)");
  visit("rate_step", s.search.rate_step, "relative step between candidate rates");
  visit("phases", s.search.phases, "sub-frame phases per candidate rate in the coarse search");
  visit("coarse_exposure", s.search.exposure, "exposure assumed by the coarse search, camera frames");
  visit("max_missing_share", s.search.max_missing_share, "share of a code's frames that may be dropped");
  visit("detrend_frames", s.search.detrend_frames, "code search: mean over +- this many frames subtracted");
  visit("offset_range", s.fit.offset_range, "sub-frame fit range around the coarse offset, camera frames");
  visit("offset_step", s.fit.offset_step, "grid step of the sub-frame fit, camera frames");
  visit("min_exposure", s.fit.min_exposure, "shortest exposure the fit tries, camera frames");
  visit("max_exposure", s.fit.max_exposure, "longest exposure the fit tries, camera frames");
  visit("exposure_steps", s.fit.exposure_steps, "exposures the fit tries between the two");
  visit("feasible_chi2", s.fit.feasible_chi2, "cost excess (residual variances per frame) that fits as well");
  visit("plateau_tolerance", s.fit.plateau_tolerance, "cost excess (share of signal variance) that fits as well");
  visit("fit_iterations", s.fit.max_iterations, "Levenberg-Marquardt iterations of the fit");
  visit("gain_drift", s.fit.gain_drift, "code levels drift linearly within a window (automatic exposure)");
}

template <typename IngestOptionsT, typename Visitor>
void VisitIngestOptions(IngestOptionsT& o, Visitor&& visit) {
  VisitSyncOptions(o.sync, visit);
  visit("exposure_s", o.exposure_s, "known exposure time of the cameras, seconds (0: estimate it)");
  visit("margin", o.pick.margin, "projector frames kept clear of each pattern change");
  visit("average_frames", o.pick.average_frames, "clean frames averaged per pattern before detection");
  visit("spare_frames", o.pick.spare_frames, "later clean frames standing in for dropped ones");
  visit("max_clock_drift", o.pick.max_clock_drift, "largest relative camera clock drift");
  visit("use_roi", o.use_roi, "detect in regions of interest once the homography is known");
  visit("explore_interval", o.explore_interval,
        "one scale of every n-th array is searched in whole frames for markers on other surfaces (0: never)");
  visit("explore_scales", o.explore_scales, "... taking this many of the largest scales in turn");
  visit("bootstrap_downscale", o.bootstrap_downscale, "whole frames before the homography are shrunk this much");
  visit("adaptive_bootstrap", o.adaptive_bootstrap, "... and further, as far as the markers found so far allow");
  visit("refine_undistorted", o.refine_undistorted, "corners from straight edge lines in undistorted pixels");
  visit("edge_search_fraction", o.edges.search_fraction, "edge profiles reach this share of a module inwards");
  visit("edge_outward_fraction", o.edges.outward_fraction, "... and at most this share outwards");
  visit("edge_gap_share", o.edge_gap_share, "... and at most this share of the gap to the next marker");
  visit("edge_spacing_px", o.edges.spacing_px, "one edge profile every this many pixels");
  visit("edge_min_samples", o.edges.min_samples, "profiles per edge at least");
  visit("edge_max_samples", o.edges.max_samples, "profiles per edge at most");
  visit("edge_profile_samples_per_px", o.edges.profile_samples_per_px, "samples along a profile per pixel");
  visit("edge_max_profile_samples", o.edges.max_profile_samples, "samples along a profile at most");
  visit("edge_end_margin", o.edges.end_margin, "share of each edge left out at either end");
  visit("edge_min_contrast", o.edges.min_contrast, "profiles below this share of the median contrast ignored");
  visit("edge_passes", o.edges.passes, "edge fits at most, each from the previous result");
  visit("edge_tolerance_px", o.edges.tolerance_px, "edge fits stop once no corner moves by more than this");
  visit("roi_padding_fraction", o.roi.padding_fraction, "padding around a predicted marker, share of its side");
  visit("roi_padding_px", o.roi.padding_px, "padding around a predicted marker, pixels");
  visit("roi_alignment", o.roi.alignment, "regions start on multiples of this many pixels");
  visit("min_module_px", o.roi.min_module_px, "markers whose predicted cell is smaller are not searched");
  visit("border_px", o.roi.border_px, "a marker must lie this far inside the image to be searched");
  visit("max_roi_area_fraction", o.roi.max_area_fraction, "regions searching more than this share: whole frame");
  visit("max_offset_px", o.roi.max_offset_px, "largest distance of a detection from its prediction, pixels");
  visit("max_offset_fraction", o.roi.max_offset_fraction, "the same as a share of the marker side");
  visit("target_module_px", o.roi.target_module_px, "larger markers are detected shrunk to about this module");
  visit("max_downscale", o.roi.max_downscale, "largest such shrinking factor");
  visit("roi_threshold_window_px", o.roi.threshold_window_px, "ArUco's threshold window in regions (0: its own)");
  visit("roi_min_white_black_diff", o.roi.min_white_black_diff, "AprilTag's minimum contrast in regions (0: its own)");
  visit("max_scales_per_msm", o.max_scales_per_msm, "scales searched per MSM at most, the largest (0: all)");
  visit("learn_resolution", o.learn_resolution, "stop searching marker sizes the camera does not decode");
  visit("resolution_bin_px", o.resolution.bin_px, "module size bins of that record, pixels");
  visit("resolution_min_trials", o.resolution.min_trials, "markers searched in a bin before it is judged");
  visit("resolution_min_found_share", o.resolution.min_found_share, "bins found less often are given up");
  visit("homography_min_points", o.homography.min_points, "distinct MSM centres needed before the homography");
  visit("homography_min_spread", o.homography.min_spread, "their spread, share of the image diagonal");
  visit("homography_threshold_px", o.homography.ransac_threshold_px, "RANSAC threshold of the homography fit");
  visit("homography_min_inlier_share", o.homography.min_inlier_share, "share of inliers the fit needs");
  visit("homography_max_rms_px", o.homography.max_rms_px, "inlier RMS the fit must stay under");
  visit("consistency_px", o.consistency.threshold_px, "detections this far off the floor homography are dropped");
  visit("consistency_min_share", o.consistency.min_share, "share that must agree, else all are dropped");
  visit("consistency_min_positions", o.consistency.min_positions,
        "marker positions the agreeing detections must cover, else all are dropped");
  visit("consistency_max_surfaces", o.consistency.max_surfaces,
        "surfaces (floor, table top, ...) planned with and kept, one homography each");
  visit("consistency_local_neighbours", o.consistency.local_neighbours,
        "a detection is checked against this many neighbours on its surface (0: not)");
  visit("consistency_local_sigmas", o.consistency.local_sigmas,
        "... and dropped beyond this many robust sigmas of such differences");
  visit("consistency_min_local_px", o.consistency.min_local_px, "... and beyond this many pixels");
  visit("max_deviation_px", o.merge.max_deviation_px, "scales farther than this from their median are rejected");
  visit("min_scales", o.merge.min_scales, "scales an MSM needs to give a centre");
  visit("readout_bands", o.readout_bands, "image bands measuring a rolling shutter's readout (0: none)");
  visit("readout_sigmas", o.readout_sigmas, "standard deviations a readout must reach to be applied");
  visit("max_readout_sigma", o.max_readout_sigma, "... and its largest sigma, camera frames");
  visit("unmeasured_readout_frames", o.unmeasured_readout_frames,
        "readout assumed at most when it cannot be measured, camera frames (0: global shutter)");
  visit("use_timestamps", o.use_timestamps, "time from container timestamps (false: decoding order)");
  visit("max_frame_gap_s", o.max_frame_gap_s, "largest gap between frame timestamps, seconds");
  visit("mean_row_step", o.mean_row_step, "the mean luma is taken over every n-th row");
  visit("luma_gamma", o.luma_gamma, "the video's display gamma, undone before the mean (1: encoded values)");
  visit("lookback_frames", o.lookback_frames, "decoded frames kept while the start code is searched");
  visit("search_interval", o.search_interval, "frames between two searches of the start code");
  visit("detection_threads", o.detection_threads, "detection threads per camera");
  visit("max_pending_jobs", o.max_pending_jobs, "patterns waiting for detection at most");
  visit("planning_lag", o.planning_lag, "patterns are planned from the detections this many patterns back");
  visit("thumbnail_width", o.thumbnail_width, "width of the grey thumbnail of a detected frame (0: none)");
}

}  // namespace calibproj::ingest
