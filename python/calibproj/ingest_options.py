"""Options of the video ingest (``calibproj.detect``), with their defaults.

Every field maps one-to-one onto a knob of the C++ ingest (``cpp/calibproj/ingest``);
``tests/test_ingest.py`` checks that the defaults here equal the C++ ones.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class IngestOptions:
    """Knobs of synchronisation, frame picking, detection and merging.

    Synchronisation finds the start and end light codes in the per-frame mean luma
    (``cpp/calibproj/sync``); frames are picked from the resulting frame map; markers
    are detected in regions of interest predicted by the projector-to-image homography
    once the first detections give it; the scales of each MSM are merged.

    Attributes:
        min_correlation: normalised cross-correlation a light code must reach.
        max_rate_deviation: largest relative difference between the rate the two codes
            give and the video's nominal rate before they count as disagreeing.
        context_before: projector frames of known light (reference frames) used before
            each code.
        context_after: projector frames of known light used after each code.
        guard_samples: camera frames searched past the best start-code match before it
            is accepted while decoding.
        rate_search: candidate rates span the nominal rate x (1 +- rate_search).
        rate_step: relative step between candidate rates.
        phases: sub-frame phases per candidate rate in the coarse search.
        coarse_exposure: exposure assumed by the coarse search, camera frames.
        max_missing_share: share of a light code's camera frames that may be missing
            (dropped by the camera) where the code is searched; the correlation is
            taken over the frames present.
        detrend_frames: the code search compares signal and code after subtracting their
            mean over +- this many camera frames (0: not at all), so that a camera whose
            automatic exposure settles while the code plays still finds it.
        offset_range: the sub-frame fit searches +- this many camera frames around the
            coarse offset.
        offset_step: grid step of the sub-frame fit, camera frames.
        min_exposure: shortest exposure the fit tries, camera frames.
        max_exposure: longest exposure the fit tries, camera frames.
        exposure_steps: exposures the fit tries between the two.
        feasible_chi2: a frame map fits as well as the best when its cost exceeds the
            best by less than this many residual variances per frame; the offsets of
            those maps give the reported uncertainty and the exposure windows that
            count for picking clean frames.
        plateau_tolerance: a frame map also fits as well when its cost exceeds the best
            by less than this share of the signal's variance (noise-free plateaus).
        fit_iterations: Levenberg-Marquardt iterations of the fit.
        gain_drift: the black level and contrast of each code window drift linearly in
            time (a camera adjusting its exposure or gain during the code); false keeps
            them constant per window.
        exposure_s: known exposure time of the cameras, seconds, or 0 to estimate it from
            the codes. Where every light change falls at the same phase of a camera's
            frames (camera at the projector's rate or a multiple of it), a frame across a
            change only tells how its exposure splits, and the offset is known exactly
            only with the exposure.
        margin: projector frames kept clear of each pattern change, on either side.
        average_frames: clean frames averaged per pattern before detection (the most
            central ones; fewer where the camera records fewer). Three lower the sensor
            and compression noise that limits the centres under strong room light, but
            have been seen to cost a 60 fps camera on a strongly textured floor its
            markers; one is the default.
        spare_frames: further clean frames per pattern, after the first picked one, that
            stand in for picked frames the camera dropped.
        max_clock_drift: largest relative camera clock drift; widens the frames kept
            clear while decoding, before the end code is seen.
        use_roi: detect in predicted regions once the projector-to-image homography is
            known (false: whole frames at full resolution, for verification).
        explore_interval: one scale of every n-th array is searched in whole frames
            (shrunk as its markers allow) and its markers kept wherever they are found,
            so that markers moved by a surface whose homography is not known yet (a
            table top, planned where the floor would have put them) are found, and that
            surface plans the later patterns (0: never).
        explore_scales: the explored arrays take this many of the largest scales in
            turn: the largest are found from afar, smaller ones fit on a narrow table.
        bootstrap_downscale: whole frames searched before the homography is known are
            shrunk by this factor (libapriltag takes ~300 ms on a full 1080p frame);
            markers too small to survive it are found once regions take over.
        adaptive_bootstrap: with use_roi, those whole frames are shrunk further as far
            as the markers found so far allow (the next pattern's module, predicted at
            half the smallest magnification seen, near target_module_px): a zoomed
            camera that needs many patterns before its homography does not pay full
            frames for them.
        refine_undistorted: corners from straight edge lines fitted in undistorted pixels,
            starting from the detector's unrefined corners (false: the detector's own
            refinement, then the four corners undistorted); straight edges of large
            markers bend under lens distortion.
        edge_search_fraction: how far each intensity profile across an edge reaches into
            the marker, as a share of one module.
        edge_outward_fraction: how far it reaches out of the marker, at most (share of a
            module).
        edge_gap_share: ... and at most this share of the gap to the next marker of the
            pattern (markers may be only half a module apart at the largest scale).
        edge_spacing_px: one profile every this many pixels along each edge.
        edge_min_samples: profiles per edge at least.
        edge_max_samples: profiles per edge at most (large markers gain nothing from more).
        edge_profile_samples_per_px: samples along a profile per pixel.
        edge_max_profile_samples: samples along a profile at most.
        edge_end_margin: share of each edge left out at either end.
        edge_min_contrast: profiles with less contrast than this share of their edge's
            median are ignored.
        edge_passes: edge fits at most, each from the previous result (profiles centre
            on their edges over the passes).
        edge_tolerance_px: ... stopping once no corner moves by more than this.
        roi_padding_fraction: padding around a predicted marker, as a share of its side
            (the larger of this and roi_padding_px).
        roi_padding_px: padding around a predicted marker, pixels.
        roi_alignment: regions start on multiples of this many pixels.
        min_module_px: markers whose predicted cell is smaller are not searched.
        border_px: a marker must lie this far inside the image to be searched.
        max_roi_area_fraction: when the regions' pixels exceed this share of the frame's
            (both as searched, after shrinking), one whole-frame detection replaces them.
        max_offset_px: a detection must lie within the larger of this and
            max_offset_fraction of its side from its prediction, pixels.
        max_offset_fraction: see max_offset_px.
        target_module_px: a marker whose predicted module exceeds this is detected in its
            region shrunk by an integer factor bringing the module near this size (its
            corners are refined at full resolution anyway); 0 = never shrink.
        max_downscale: largest such factor.
        roi_threshold_window_px: ArUco's adaptive threshold window in regions, pixels:
            the marker's size there is known, so one window does where a whole frame
            needs several (about 1.5x faster detection on the mock OR); 0 keeps the
            detector's own.
        roi_min_white_black_diff: libapriltag's minimum white-black contrast in regions,
            grey levels: flat noisy background below it is not segmented (about 1.6x
            faster detection on the mock OR); 0 keeps the detector's own.
        max_scales_per_msm: scales searched per MSM at most: a marker is left out when
            this many larger scales of its MSM are worth searching (larger markers give
            better centres); 0 searches every scale.
        learn_resolution: stop searching markers of sizes the camera has not been
            decoding (judged per bin of predicted module size).
        resolution_bin_px: width of those bins, pixels of module size.
        resolution_min_trials: markers searched in a bin before it is judged.
        resolution_min_found_share: a bin (and every smaller size) is given up below this
            share found.
        homography_min_points: distinct MSM centres needed before the homography is trusted.
        homography_min_spread: those centres must spread over this share of the image
            diagonal.
        homography_threshold_px: RANSAC inlier threshold of the homography fit.
        homography_min_inlier_share: share of inliers the fit needs.
        homography_max_rms_px: inlier RMS the fit must stay under.
        consistency_px: every detection is checked against one homography of the floor
            (RANSAC over all of the camera's detections); those farther than this from
            its prediction (a wrong id, a frame of another pattern) are dropped.
        consistency_min_share: when fewer than this share of the detections agree on
            one homography, none of them is kept.
        consistency_min_positions: the agreeing detections must cover this many places
            (marker positions, or image points 4 consistency_px apart, whichever count is
            larger), else none is kept: a homography fits any few, so a stain decoded as
            one marker in every array would pass unchecked.
        consistency_max_surfaces: surfaces whose detections are kept, one homography
            each: the floor, then among the detections left the largest group that
            agrees on another homography (a table top, a cart left in the projection),
            if it has enough detections at enough places. The same surfaces plan the
            regions searched: each marker where the surface its projector centre lands
            on puts it.
        consistency_local_neighbours: the threshold above leaves room for lenses known
            only roughly, whose residuals vary slowly over the image; a marker partly
            hidden by a table or cut by its shadow decodes with its centre a pixel or
            two off and stands out against its neighbours: each detection's residual is
            compared with the median residual of this many nearest detections of other
            markers on its surface (0: no such check).
        consistency_local_sigmas: ... and dropped when the difference exceeds this many
            robust standard deviations of all such differences,
        consistency_min_local_px: ... and this many pixels.
        max_deviation_px: scales of an MSM farther than this from their median are
            rejected.
        min_scales: scales an MSM needs (after rejection) to give a centre.
        readout_bands: horizontal bands of the image whose light codes are fitted
            separately: their offsets give a rolling shutter's readout time (0: not
            measured).
        readout_sigmas: a readout beyond this many standard deviations moves the frame
            map to the first row (the frame's timestamp) and widens each frame's window
            to every row's exposure, so that a picked frame shows one pattern in all
            its rows.
        max_readout_sigma: ... provided it is known to this many camera frames (1 sigma);
            a readout known less well is reported, not used; the offset, which then
            refers to the rows that see the projection, has its uncertainty widened by
            the readout (plus two sigma) times the share of the image between those
            rows and the farther of the first and last rows (half when the projection
            fills the image).
        unmeasured_readout_frames: the readout of a camera where it cannot be measured
            (no band of rows sees a light change) may be anything up to this many
            camera frames: its offset's uncertainty widens by that share of it (0
            assumes a global shutter; 1, the default, any rolling shutter).
        use_timestamps: time comes from the container's frame timestamps: each frame
            is placed on the camera's frame grid, so dropped frames leave gaps instead
            of shifting every later frame (false: time from the decoding order, for
            containers whose timestamps are wrong).
        max_frame_gap_s: a gap longer than this between consecutive frames' timestamps
            (a paused recording, a corrupt timestamp) fails the camera.
        mean_row_step: the mean luma is taken over every n-th row.
        luma_gamma: the video's display gamma, undone per pixel before the mean, so that
            a frame across a light change measures the exposure-weighted mean (1 keeps
            the encoded values).
        lookback_frames: decoded frames kept while the start code is searched.
        search_interval: frames between two searches of the start code.
        detection_threads: detection threads per camera.
        max_pending_jobs: patterns waiting for detection at most (bounds memory).
        planning_lag: a pattern's regions are planned from the detections of the patterns
            at least this many before it, whatever the threads' timing, so that results
            do not depend on how fast detection keeps up.
        thumbnail_width: width in pixels of the grey copy of the first frame sent to
            detection, which the report draws the camera's detections on (0: none).
    """

    min_correlation: float = 0.8
    max_rate_deviation: float = 0.01
    context_before: int = 30
    context_after: int = 6
    guard_samples: int = 4
    rate_search: float = 0.02
    rate_step: float = 0.002
    phases: int = 4
    coarse_exposure: float = 0.5
    max_missing_share: float = 0.25
    detrend_frames: int = 8
    offset_range: float = 1.0
    offset_step: float = 0.02
    min_exposure: float = 0.02
    max_exposure: float = 1.0
    exposure_steps: int = 50
    feasible_chi2: float = 9.0
    plateau_tolerance: float = 1e-6
    fit_iterations: int = 50
    gain_drift: bool = True
    exposure_s: float = 0.0
    margin: float = 0.1
    average_frames: int = 1
    spare_frames: int = 2
    max_clock_drift: float = 2e-4
    use_roi: bool = True
    explore_interval: int = 1
    explore_scales: int = 3
    bootstrap_downscale: int = 1
    adaptive_bootstrap: bool = True
    refine_undistorted: bool = True
    edge_search_fraction: float = 0.45
    edge_outward_fraction: float = 0.45
    edge_gap_share: float = 0.4
    edge_spacing_px: float = 1.0
    edge_min_samples: int = 6
    edge_max_samples: int = 32
    edge_profile_samples_per_px: float = 5.0
    edge_max_profile_samples: int = 40
    edge_end_margin: float = 0.15
    edge_min_contrast: float = 0.5
    edge_passes: int = 6
    edge_tolerance_px: float = 0.002
    roi_padding_fraction: float = 0.25
    roi_padding_px: int = 16
    roi_alignment: int = 8
    min_module_px: float = 1.5
    border_px: int = 4
    max_roi_area_fraction: float = 0.5
    max_offset_px: float = 4.0
    max_offset_fraction: float = 0.25
    target_module_px: float = 4.0
    max_downscale: int = 8
    roi_threshold_window_px: int = 13
    roi_min_white_black_diff: int = 20
    max_scales_per_msm: int = 4
    learn_resolution: bool = True
    resolution_bin_px: float = 0.25
    resolution_min_trials: int = 24
    resolution_min_found_share: float = 0.05
    homography_min_points: int = 8
    homography_min_spread: float = 0.02
    homography_threshold_px: float = 2.0
    homography_min_inlier_share: float = 0.8
    homography_max_rms_px: float = 1.0
    consistency_px: float = 3.0
    consistency_min_share: float = 0.3
    consistency_min_positions: int = 3
    consistency_max_surfaces: int = 3
    consistency_local_neighbours: int = 8
    consistency_local_sigmas: float = 5.0
    consistency_min_local_px: float = 0.5
    max_deviation_px: float = 0.5
    min_scales: int = 1
    readout_bands: int = 16
    readout_sigmas: float = 3.0
    max_readout_sigma: float = 0.1
    unmeasured_readout_frames: float = 1.0
    use_timestamps: bool = True
    max_frame_gap_s: float = 2.0
    mean_row_step: int = 2
    luma_gamma: float = 2.2
    lookback_frames: int = 16
    search_interval: int = 4
    detection_threads: int = 1
    max_pending_jobs: int = 4
    planning_lag: int = 4
    thumbnail_width: int = 640

    def replace(self, **changes: Any) -> IngestOptions:
        """A copy with some fields changed; ValueError naming an unknown field."""
        known = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(changes) - known)
        if unknown:
            raise ValueError(f"unknown ingest option(s) {', '.join(unknown)} (choose from {', '.join(sorted(known))})")
        return dataclasses.replace(self, **changes)

    def to_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of ``calibproj._core.ingest.ingest_camera``."""
        return dataclasses.asdict(self)


def sync_kwargs(options: IngestOptions, camera_fps: float) -> dict[str, Any]:
    """The synchronisation part of the options (``calibproj._core.sync`` keywords), the
    exposure in the camera's frames."""
    from calibproj import _core

    names = set(_core.sync.option_defaults())
    kwargs = {name: value for name, value in options.to_kwargs().items() if name in names}
    kwargs["fixed_exposure"] = options.exposure_s * camera_fps
    return kwargs
