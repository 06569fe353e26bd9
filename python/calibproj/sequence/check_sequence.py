"""The check projection: a few of the calibrated arrays shown again, in at most 8 s.

``calibproj check`` tests each camera of a stored calibration on new observations of
points whose 3D positions the calibration knows, so the check projection shows arrays
the calibration was made from, at their own centres and scales: its point ids are the
calibration's. ``plan_check`` picks them from a first calibration's observations: the
arrays that give every registered camera, the zoomed one included, the most of its
calibrated points, until each has ``points_per_camera`` of them or the time is spent.
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

from calibproj.sequence.builder import ShownPattern, overhead_seconds, pattern_budget, reassembled
from calibproj.sequence.codes import MAX_DEGREE, MIN_DEGREE
from calibproj.sequence.sequence import Sequence

log = logging.getLogger(__name__)

# Observations a camera needs to be tested (calibproj.check_and_repair.CheckOptions's
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
    """

    max_seconds: float = 8.0
    points_per_camera: int = 30
    code_degree: int = 4
    reference_frames: int = 8

    def __post_init__(self) -> None:
        if not 0.0 < self.max_seconds <= 600.0:
            raise ValueError(f"max_seconds must be in (0, 600], got {self.max_seconds}")
        if not 6 <= self.points_per_camera <= 100_000:
            raise ValueError(f"points_per_camera must be in [6, 100000], got {self.points_per_camera}")
        if not MIN_DEGREE <= self.code_degree <= MAX_DEGREE:
            raise ValueError(f"code_degree must be in [{MIN_DEGREE}, {MAX_DEGREE}], got {self.code_degree}")
        if not 1 <= self.reference_frames <= 300:
            raise ValueError(f"reference_frames must be in [1, 300], got {self.reference_frames}")


def plan_check(results: str | os.PathLike, sequences: list[Sequence],
               options: CheckSequenceOptions | None = None) -> tuple[Sequence, dict[str, int]]:
    """The check sequence for the calibration in the folder ``results``, made from
    ``sequences`` (the one it was calibrated from and, when merged, the first one), and
    per registered camera the calibrated points it will see."""
    from calibproj.calibration import Calibration
    from calibproj.results import TRACKS_FILE
    from calibproj.tracks import Tracks

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
    shown = [pattern for array in sorted(chosen) for pattern in candidates[array]]
    sequence = reassembled(base, base.layout, base.centres, shown, code_degree=options.code_degree,
                           reference_frames=options.reference_frames)
    seen = {name: int(sum(per_array.get(array, 0) for array in chosen)) for name, per_array in counts.items()}
    for name, points in seen.items():
        if points < min(options.points_per_camera, MIN_TESTED_POINTS):
            log.warning("camera %s sees only %d calibrated points in the check projection: it will be unknown",
                        name, points)
    return sequence, seen


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
