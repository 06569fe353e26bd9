"""The check projection: a few of the calibrated arrays shown again, in at most 8 s.

``calibproj check`` tests each camera of a stored calibration on new observations of
points whose 3D positions the calibration knows, so the check projection shows arrays
the calibration was made from, at their own centres and scales: its point ids are the
calibration's. ``plan_check`` picks them from a first calibration's observations: the
arrays that give every registered camera, the zoomed one included, the most of its
calibrated points, until each has ``points_per_camera`` of them; then, with the time
left, the arrays that most sharpen what each camera's test can resolve (how far the
working volume may seem to move in its image for the detection noise: points spread
over a camera's view fix its pose, one patch of them leaves it free to turn).
A calibration merged with a densified projection is checked from both sequences (the
densified one holds every centre; its own arrays are where the zoomed camera looks).
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calibproj import _core
from calibproj.sequence.builder import ShownPattern, overhead_seconds, pattern_budget, reassembled
from calibproj.sequence.codes import MAX_DEGREE, MIN_DEGREE
from calibproj.sequence.sequence import Sequence

log = logging.getLogger(__name__)

# Observations a camera needs to be tested (calibproj.check.repair.CheckOptions's
# default min_points: a pose has six parameters).
MIN_TESTED_POINTS = 6


@dataclass(frozen=True)
class CheckSequenceOptions:
    """How the check projection is planned.

    Attributes:
        max_seconds: longest check projection, light codes and reference frames included.
        points_per_camera: calibrated points each camera should see in it (enough to
            test a pose, its six parameters, many times over); a camera that had fewer
            in the calibration gets all the arrays it saw that fit the time.
        code_degree: its light codes are m-sequences of 2^code_degree - 1 bits: 4 (15
            bits, 1.5 s each at 30 fps) where a calibration's 5 take 3.1 s, since a check
            projection is short and its patterns few.
        reference_frames: frames of each white and black block around the codes (8 where
            a calibration's sequence has 15): with the codes, 4.6 s of the check's time
            instead of 9.2 s.
        target_shift_px: once every camera has its points, arrays are added while they
            bring a camera's resolvable volume shift (1 sigma) down towards this, in
            pixels; a quarter of the check's default tolerance.
        noise_px: the detection noise (px per coordinate) that resolution is planned for:
            the noise of a rendered room's centres with the check's model error.
    """

    max_seconds: float = 8.0
    points_per_camera: int = 30
    code_degree: int = 4
    reference_frames: int = 8
    target_shift_px: float = 0.125
    noise_px: float = 0.1

    def __post_init__(self) -> None:
        if not 0.0 < self.max_seconds <= 600.0:
            raise ValueError(f"max_seconds must be in (0, 600], got {self.max_seconds}")
        if not 6 <= self.points_per_camera <= 100_000:
            raise ValueError(f"points_per_camera must be in [6, 100000], got {self.points_per_camera}")
        if not MIN_DEGREE <= self.code_degree <= MAX_DEGREE:
            raise ValueError(f"code_degree must be in [{MIN_DEGREE}, {MAX_DEGREE}], got {self.code_degree}")
        if not 1 <= self.reference_frames <= 300:
            raise ValueError(f"reference_frames must be in [1, 300], got {self.reference_frames}")
        if not 1e-3 <= self.target_shift_px <= 1e3:
            raise ValueError(f"target_shift_px must be in [0.001, 1000], got {self.target_shift_px}")
        if not 1e-3 <= self.noise_px <= 100.0:
            raise ValueError(f"noise_px must be in [0.001, 100], got {self.noise_px}")


def plan_check(results: str | os.PathLike, sequences: list[Sequence],
               options: CheckSequenceOptions | None = None
               ) -> tuple[Sequence, dict[str, int], dict[str, float | None]]:
    """The check sequence for the calibration in the folder ``results``, made from
    ``sequences`` (the one it was calibrated from and, when merged, the first one); per
    registered camera the calibrated points it will see; and per camera what its test
    will resolve: how far the working volume may seem to move in its image (1 sigma, px,
    at ``options.noise_px``), None where the camera's intrinsics or points do not say."""
    from calibproj.formats.calibration import Calibration
    from calibproj.formats.results import TRACKS_FILE
    from calibproj.formats.tracks import Tracks

    options = options or CheckSequenceOptions()
    folder = Path(results)
    calibration = Calibration.load(folder)
    tracks = Tracks.read(folder / TRACKS_FILE)
    base = _common_base(sequences)
    candidates = _patterns_by_array(sequences, base)
    counts = _calibrated_points_per_array(calibration, tracks, base)
    budget = pattern_budget(base, options.max_seconds, options.code_degree, options.reference_frames)
    if budget < 1:
        overhead = overhead_seconds(base, options.code_degree, options.reference_frames)
        raise ValueError(f"{options.max_seconds:g} s leave no time for patterns: the light codes and reference "
                         f"frames alone take {overhead:.1f} s")
    chosen = _choose_arrays(counts, candidates, budget, options.points_per_camera)
    if not chosen:
        raise ValueError(f"{folder}: no array of these sequences holds a calibrated point; give the sequence "
                         f"the results were calibrated from")
    views = _camera_views(calibration, tracks, base, folder)
    chosen = _spread_arrays(views, chosen, candidates, budget, options)
    shown = [pattern for array in sorted(chosen) for pattern in candidates[array]]
    sequence = reassembled(base, base.layout, base.centres, shown, code_degree=options.code_degree,
                           reference_frames=options.reference_frames)
    seen = {name: int(sum(per_array.get(array, 0) for array in chosen)) for name, per_array in counts.items()}
    resolution: dict[str, float | None] = {}
    for name, points in seen.items():
        sigma = views[name].shift_sigma(chosen, options.noise_px) if name in views else math.inf
        resolution[name] = sigma if math.isfinite(sigma) else None
        if points < min(options.points_per_camera, MIN_TESTED_POINTS):
            log.warning("camera %s sees only %d calibrated points in the check projection: it will be unknown",
                        name, points)
    return sequence, seen, resolution


def _common_base(sequences: list[Sequence]) -> Sequence:
    """The sequence holding every other's centres (the densified one of a merge)."""
    if not sequences:
        raise ValueError("no sequence to plan the check projection from")
    base = max(sequences, key=lambda sequence: sequence.layout.arrays)
    for sequence in sequences:
        arrays = sequence.layout.arrays
        same = (sequence.markers.spec == base.markers.spec and sequence.projector == base.projector
                and np.allclose(sequence.centres, base.centres[:arrays]))
        if not same:
            raise ValueError("the sequences are not of one projection: their markers, projector or centres differ")
    return base


def _patterns_by_array(sequences: list[Sequence], base: Sequence) -> dict[int, list[ShownPattern]]:
    """Per array the patterns the sequences show of it, as scales of ``base``'s layout."""
    layout = base.layout
    by_array: dict[int, list[ShownPattern]] = {}
    for sequence in sequences:
        for pattern in sequence.patterns:
            index = next((k for k, scale in enumerate(layout.scales)
                          if math.isclose(layout.marker_side(scale), pattern.marker_side_px)), None)
            if index is None or pattern.array in by_array and any(
                    shown.scale_index == index for shown in by_array[pattern.array]):
                continue
            by_array.setdefault(pattern.array, []).append(ShownPattern(pattern.array, index, pattern.omitted))
    return by_array


def _calibrated_points_per_array(calibration, tracks, base: Sequence) -> dict[str, dict[int, int]]:
    """Per registered camera, per array: its observations of calibrated points."""
    markers_per_array = base.layout.markers_per_array
    calibrated = set(calibration.point_ids.tolist())
    counts: dict[str, dict[int, int]] = {}
    for name in calibration.registered:
        ids, _ = tracks.observations(name) if name in tracks.camera_names else (np.zeros(0, np.int64), None)
        kept = np.array([int(i) for i in ids if int(i) in calibrated], dtype=np.int64)
        arrays, number = np.unique(kept // markers_per_array, return_counts=True)
        counts[name] = dict(zip(arrays.tolist(), number.tolist()))
    return counts


def _choose_arrays(counts: dict[str, dict[int, int]], candidates: dict[int, list[ShownPattern]], budget: int,
                   points_per_camera: int) -> set[int]:
    """Greedy: the array that brings the cameras still short of points the most of
    them per pattern shown, until each has enough or the patterns run out."""
    have = {name: 0 for name in counts}
    chosen: set[int] = set()
    used = 0
    while True:
        best, best_gain = None, 0.0
        for array, patterns in candidates.items():
            if array in chosen or used + len(patterns) > budget:
                continue
            # A camera's shortfall counts relative to what it needs: the zoomed camera's
            # handful matters as much as a far camera's hundreds.
            gain = sum(min(per_array.get(array, 0), points_per_camera - have[name]) / points_per_camera
                       for name, per_array in counts.items() if have[name] < points_per_camera)
            if gain / len(patterns) > best_gain:
                best, best_gain = array, gain / len(patterns)
        if best is None:
            return chosen
        chosen.add(best)
        used += len(candidates[best])
        for name, per_array in counts.items():
            have[name] += per_array.get(best, 0)


@dataclass
class _CameraView:
    """One registered camera as the planner sees it: its stored pinhole, its image size,
    the working volume, and per array the stored points it observed."""

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    size: tuple[float, float]
    volume: np.ndarray
    points_by_array: dict[int, np.ndarray]

    def shift_sigma(self, arrays: set[int], noise_px: float) -> float:
        """How far (1 sigma, px) a check on these arrays' points could tell the working
        volume moved in this camera's image."""
        points = [self.points_by_array[a] for a in arrays if a in self.points_by_array]
        if not points:
            return math.inf
        return float(_core.check.predicted_shift_sigma(self.K, self.R, self.t, np.concatenate(points), self.volume,
                                                       *self.size, noise_px))


def _camera_views(calibration, tracks, base: Sequence, folder: Path) -> dict[str, _CameraView]:
    from calibproj.formats.intrinsics import intrinsics_of_cameras
    from calibproj.formats.results import INTRINSICS_DIR

    if not (folder / INTRINSICS_DIR).is_dir():
        return {}  # planned by the points alone
    cameras, _ = intrinsics_of_cameras(folder / INTRINSICS_DIR, list(calibration.registered))
    volume = np.asarray(_core.check.working_volume(calibration))
    stored = {int(i): k for k, i in enumerate(calibration.point_ids.tolist())}
    views: dict[str, _CameraView] = {}
    for name in calibration.registered:
        camera = cameras.get(name)
        if camera is None or camera.resolution is None or name not in tracks.camera_names:
            continue  # planned by its points alone
        ids, _ = tracks.observations(name)
        rows = np.array([stored[int(i)] for i in ids if int(i) in stored], dtype=np.int64)
        arrays = calibration.point_ids[rows] // base.layout.markers_per_array
        R, t = calibration.poses[name]
        views[name] = _CameraView(np.asarray(camera.K, float), R, t, tuple(map(float, camera.resolution)), volume,
                                  {int(a): calibration.points[rows[arrays == a]] for a in np.unique(arrays)})
    return views


def _spread_arrays(views: dict[str, _CameraView], chosen: set[int], candidates: dict[int, list[ShownPattern]],
                   budget: int, options: CheckSequenceOptions) -> set[int]:
    """Greedy, with the patterns ``chosen`` leaves: the array that brings the cameras'
    resolvable volume shifts down the most (in log, each down to the target) per
    pattern shown, while one does."""
    chosen = set(chosen)
    used = sum(len(candidates[array]) for array in chosen)

    def cost(name: str, arrays: set[int]) -> float:
        return math.log(max(views[name].shift_sigma(arrays, options.noise_px), options.target_shift_px))

    costs = {name: cost(name, chosen) for name in views}
    while True:
        best, best_gain, best_costs = None, 0.0, {}
        for array, patterns in candidates.items():
            if array in chosen or used + len(patterns) > budget:
                continue
            # Only the cameras that see the array and still short of the target change.
            changed = {name: cost(name, chosen | {array}) for name, view in views.items()
                       if array in view.points_by_array and costs[name] > math.log(options.target_shift_px)}
            gain = sum(0.0 if math.isinf(value) else min(costs[name] - value, 1e3)
                       for name, value in changed.items()) / len(patterns)
            if gain > best_gain:
                best, best_gain, best_costs = array, gain, changed
        if best is None:
            return chosen
        chosen.add(best)
        used += len(candidates[best])
        costs.update(best_costs)
