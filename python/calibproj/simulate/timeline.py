"""Time in a rendered simulation: what the projector shows when, and when cameras expose.

The sequence clock starts (t = 0) when projector frame 0 comes on; frame ``k`` is shown
during ``[k / fps, (k + 1) / fps)``. Before frame 0 and after the last frame the
projector is black. A camera starts recording ``start_offset_s`` seconds before the
sequence starts (a negative offset: after), so its frame ``j`` exposes during
``[j / camera_fps - start_offset_s, ... + exposure_s)``; the frame is the
exposure-weighted average of what the projector showed meanwhile.

Consecutive projector frames with the same content form a *run*; a content is
named by a key, ``("pattern", index)`` for an MSM pattern and ``("flat", level)``
for a uniform frame (light-code bits, reference frames, black), so a renderer warps
each distinct content once.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

ContentKey = tuple[str, int]
BLACK: ContentKey = ("flat", 0)
# Shares of an exposure below this are rounding residue at run boundaries, dropped.
MIN_SHARE = 1e-6


def content_key(sequence: Any, frame: int) -> ContentKey:
    """Key of what projector frame ``frame`` of a sequence shows."""
    pattern = sequence.pattern_index_at(frame)
    if pattern is not None:
        return ("pattern", int(pattern))
    image = sequence.frame(frame)
    level = int(image.flat[0])
    if image.min() != level or image.max() != level:
        # Not uniform and not a pattern: a content of its own, never merged.
        return ("frame", int(frame))
    return ("flat", level)


def content_image(sequence: Any, key: ContentKey) -> np.ndarray:
    """Projector image (``uint8``, ``(height, width)``) of a content key."""
    kind, value = key
    if kind == "pattern":
        return sequence.pattern_image(value)
    if kind == "frame":
        return sequence.frame(value)
    width, height = sequence.projector
    return np.full((height, width), value, dtype=np.uint8)


@dataclass(frozen=True)
class ProjectionTimeline:
    """Runs of identical projector content on the sequence clock.

    Attributes:
        fps: projector frame rate.
        run_starts: first projector frame of every run, increasing, ``run_starts[0] == 0``.
        run_keys: content key of every run.
        frame_count: projector frames in the sequence.
    """

    fps: float
    run_starts: tuple[int, ...]
    run_keys: tuple[ContentKey, ...]
    frame_count: int

    @classmethod
    def from_sequence(cls, sequence: Any) -> ProjectionTimeline:
        starts: list[int] = []
        keys: list[ContentKey] = []
        for frame in range(sequence.frame_count):
            key = content_key(sequence, frame)
            if not keys or key != keys[-1]:
                starts.append(frame)
                keys.append(key)
        return cls(float(sequence.fps), tuple(starts), tuple(keys), int(sequence.frame_count))

    @property
    def duration_s(self) -> float:
        return self.frame_count / self.fps

    def run_interval(self, run: int) -> tuple[float, float]:
        """Start and end time of a run, seconds on the sequence clock."""
        end_frame = self.run_starts[run + 1] if run + 1 < len(self.run_starts) else self.frame_count
        return self.run_starts[run] / self.fps, end_frame / self.fps

    def weights(self, start_s: float, end_s: float) -> dict[ContentKey, float]:
        """Share of the window ``[start_s, end_s)`` during which each content was shown
        (black before and after the sequence); the shares add up to 1."""
        if not end_s > start_s:
            raise ValueError(f"empty exposure window [{start_s}, {end_s})")
        length = end_s - start_s
        shares: dict[ContentKey, float] = {}

        def add(key: ContentKey, begin: float, end: float) -> None:
            overlap = min(end, end_s) - max(begin, start_s)
            if overlap > 0:
                shares[key] = shares.get(key, 0.0) + overlap / length

        for key, begin, end in self._shown(start_s, end_s):
            add(key, begin, end)
        kept = {key: share for key, share in shares.items() if share >= MIN_SHARE}
        total = sum(kept.values())
        return {key: share / total for key, share in kept.items()}

    def row_weights(self, start_s: float, exposure_s: float, readout_s: float,
                    rows: int) -> dict[ContentKey, float | np.ndarray]:
        """``weights`` for a rolling shutter: row ``y`` exposes during
        ``[start_s + readout_s * y / rows, ... + exposure_s)``. A content's share is a
        ``(rows, 1)`` array where it differs between rows, else a number."""
        if readout_s <= 0:
            return self.weights(start_s, start_s + exposure_s)
        starts = start_s + readout_s * np.arange(rows) / rows
        ends = starts + exposure_s
        shares: dict[ContentKey, np.ndarray] = {}

        def add(key: ContentKey, begin: float, end: float) -> None:
            overlap = np.clip(np.minimum(end, ends) - np.maximum(begin, starts), 0.0, None)
            if overlap.max() > 0:
                shares[key] = shares.get(key, 0.0) + overlap / exposure_s

        for key, begin, end in self._shown(start_s, float(ends[-1])):
            add(key, begin, end)
        kept = {key: share for key, share in shares.items() if share.max() >= MIN_SHARE}
        total = sum(kept.values())
        out: dict[ContentKey, float | np.ndarray] = {}
        for key, share in kept.items():
            share = share / total
            uniform = np.ptp(share) < MIN_SHARE
            out[key] = float(share[0]) if uniform else share.astype(np.float32)[:, None]
        return out

    def _shown(self, start_s: float, end_s: float) -> Iterator[tuple[ContentKey, float, float]]:
        """``(key, begin, end)`` of the runs that may overlap ``[start_s, end_s)``, and of
        the black before and after the sequence."""
        yield BLACK, -math.inf, 0.0
        yield BLACK, self.duration_s, math.inf
        first_frame = max(0, math.floor(start_s * self.fps))
        run = max(0, bisect.bisect_right(self.run_starts, first_frame) - 1)
        while run < len(self.run_starts):
            begin, end = self.run_interval(run)
            if begin >= end_s:
                break
            yield self.run_keys[run], begin, end
            run += 1

    def key_interval(self, key: ContentKey) -> tuple[float, float]:
        """Start and end time of the (first) run showing ``key``."""
        run = self.run_keys.index(key)
        return self.run_interval(run)


@dataclass(frozen=True)
class CameraClock:
    """When a camera's frames expose, on the sequence clock.

    Frame ``j`` is slot ``j`` of the camera's frame grid: its exposure starts at
    ``j / fps - start_offset_s + jitter_s[j]``. Frames in ``dropped`` were never
    recorded (the video has a gap in its timestamps there); the first frame is always
    recorded, so the video's first timestamp is slot 0.

    Attributes:
        fps: camera frame rate.
        start_offset_s: the camera starts recording this long before the sequence.
        exposure_s: exposure time of every frame.
        frame_count: frame slots from the first recorded frame to the last.
        jitter_s: per-slot deviation of the exposure start from the grid, seconds
            (empty: none).
        dropped: slots the camera dropped, increasing.
        readout_s: rolling shutter readout (the last row starts this much after the
            first; 0: global shutter). Exposure starts are those of the first row.
    """

    fps: float
    start_offset_s: float
    exposure_s: float
    frame_count: int
    jitter_s: tuple[float, ...] = ()
    dropped: tuple[int, ...] = ()
    readout_s: float = 0.0

    @classmethod
    def covering(cls, fps: float, start_offset_s: float, exposure_s: float, duration_s: float,
                 tail_s: float, readout_s: float = 0.0) -> CameraClock:
        """A clock recording from its start until ``tail_s`` after a sequence of ``duration_s``."""
        frame_count = math.ceil((start_offset_s + duration_s + tail_s) * fps - 1e-9)
        return cls(fps, start_offset_s, exposure_s, frame_count, readout_s=readout_s)

    def with_timing(self, jitter_std_s: float, drop_rate: float, rng: np.random.Generator) -> CameraClock:
        """The same clock with frame timing jitter (Gaussian, clipped to 3 sigma) and
        frames dropped at random (never the first or the last)."""
        jitter = ()
        if jitter_std_s > 0:
            draws = np.clip(rng.standard_normal(self.frame_count), -3.0, 3.0) * jitter_std_s
            jitter = tuple(float(value) for value in draws)
        dropped = ()
        if drop_rate > 0 and self.frame_count > 2:
            lost = np.flatnonzero(rng.random(self.frame_count - 2) < drop_rate) + 1
            dropped = tuple(int(frame) for frame in lost)
        return replace(self, jitter_s=jitter, dropped=dropped)

    @property
    def recorded(self) -> np.ndarray:
        """Slots of the frames in the video, increasing."""
        return np.setdiff1d(np.arange(self.frame_count), np.asarray(self.dropped, dtype=int))

    def exposure_start(self, frame: int | np.ndarray) -> float | np.ndarray:
        start = frame / self.fps - self.start_offset_s
        if not self.jitter_s:
            return start
        if isinstance(frame, np.ndarray):
            return start + np.asarray(self.jitter_s)[frame]
        return start + self.jitter_s[frame]

    def timestamps(self) -> np.ndarray:
        """Container timestamps of the recorded frames: their exposure starts, seconds
        after the first frame's."""
        recorded = self.recorded
        return self.exposure_start(recorded) - self.exposure_start(0)

    def window(self, frame: int) -> tuple[float, float]:
        start = self.exposure_start(frame)
        return start, start + self.exposure_s

    def frames_inside(self, start_s: float, end_s: float) -> np.ndarray:
        """Recorded frames whose whole exposure (every row's) lies inside ``[start_s, end_s]``."""
        frames = self.recorded
        starts = self.exposure_start(frames)
        # A little slack so that a window touching the interval's edge counts as inside.
        slack = 1e-9
        last_end = starts + self.readout_s + self.exposure_s
        return frames[(starts >= start_s - slack) & (last_end <= end_s + slack)]
