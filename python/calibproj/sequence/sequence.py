"""The projection sequence: what the projector shows in every frame, and its file.

A sequence is a timeline of contiguous segments (white and black reference frames,
the start light code, the MSM patterns, the end light code) at the projector's frame
rate. Each pattern shows one array of MSMs at one scale for ``frames_per_pattern``
frames; patterns are ordered array-major (array 0 at every scale, then array 1, ...).
``sequence.json`` (``calibproj.sequence/1``) holds everything needed to decode a
recording: marker family and colours, projector resolution and frame rate, layout
parameters, every marker centre (per array, the same at every scale), the frames of
every pattern and segment, and the light codes.
"""

from __future__ import annotations

import bisect
import functools
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibproj.sequence.codes import LightCode
from calibproj.sequence.layout import MsmLayout
from calibproj.sequence.markers import marker_bits
from calibproj.sequence.raster import draw_cells
from calibproj.formats.jsonio import FormatError, write_json

KIND = "sequence"  # the schema tag calibproj.sequence/1
MAJOR = 1
# Patterns kept rendered per sequence: consecutive frames mostly share one pattern, so
# a few suffice for renderers that walk the timeline (one 1080p pattern is 2 MB).
DEFAULT_PATTERN_CACHE = 8


@dataclass(frozen=True)
class Segment:
    """A run of frames of one kind, ``first_frame..last_frame`` inclusive."""

    kind: str
    first_frame: int
    last_frame: int

    @property
    def frame_count(self) -> int:
        return self.last_frame - self.first_frame + 1


@dataclass(frozen=True)
class Pattern:
    """One array of MSMs at one scale, shown on ``first_frame..last_frame`` (inclusive).

    ``omitted`` lists the markers of the array left out at this scale (they would
    have overlapped another marker or left the image).
    """

    array: int
    scale_index: int
    scale: float
    marker_side_px: float
    first_frame: int
    last_frame: int
    omitted: tuple[int, ...] = ()


@dataclass(frozen=True)
class MarkerSystem:
    """The marker family of a sequence and how it is drawn.

    ``grid_cells`` is the drawn marker's side in modules (border included) and
    ``quad_cells`` that of the square whose corners the detector returns; both are
    centred on the MSM centre. ``inverted``: white markers on black.
    """

    spec: str
    system: str
    family: str
    grid_cells: int
    quad_cells: int
    id_count: int
    inverted: bool


@dataclass
class Sequence:
    """A projection sequence; build one with :func:`calibproj.sequence.build_sequence`
    or read one with :meth:`load`."""

    markers: MarkerSystem
    projector: tuple[int, int]
    fps: float
    layout: MsmLayout
    min_gap_modules: float
    frames_per_pattern: int
    centres: np.ndarray
    patterns: list[Pattern]
    segments: list[Segment]
    start_code: LightCode
    end_code: LightCode
    pattern_cache_size: int = DEFAULT_PATTERN_CACHE
    _cache: Any = field(default=None, init=False, repr=False, compare=False)
    _bits: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    _flats: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    _core_sequence: Any = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.centres = np.asarray(self.centres, dtype=np.float64)
        self._cache = functools.lru_cache(maxsize=self.pattern_cache_size)(self._render_pattern)

    # ----------------------------------------------------------------- timeline

    @property
    def frame_count(self) -> int:
        return self.segments[-1].last_frame + 1

    @property
    def duration_s(self) -> float:
        return self.frame_count / self.fps

    @property
    def point_count(self) -> int:
        """Distinct MSM centres: arrays x markers per array."""
        return self.centres.shape[0] * self.centres.shape[1]

    def segment_at(self, frame: int) -> Segment:
        """The segment that frame ``frame`` belongs to."""
        self._check_frame(frame)
        firsts = [segment.first_frame for segment in self.segments]
        return self.segments[bisect.bisect_right(firsts, frame) - 1]

    def pattern_index_at(self, frame: int) -> int | None:
        """Index in :attr:`patterns` of the pattern shown at ``frame``, or None."""
        self._check_frame(frame)
        firsts = [pattern.first_frame for pattern in self.patterns]
        index = bisect.bisect_right(firsts, frame) - 1
        if index >= 0 and frame <= self.patterns[index].last_frame:
            return index
        return None

    def markers_shown(self, pattern_index: int) -> np.ndarray:
        """Marker indices (= ids) drawn in a pattern, ascending."""
        pattern = self.patterns[pattern_index]
        shown = np.ones(self.centres.shape[1], dtype=bool)
        shown[list(pattern.omitted)] = False
        return np.flatnonzero(shown)

    def _check_frame(self, frame: int) -> None:
        if not 0 <= frame < self.frame_count:
            raise IndexError(f"frame {frame} outside the sequence (0..{self.frame_count - 1})")

    # ---------------------------------------------------------------- rendering

    def frame(self, index: int) -> np.ndarray:
        """Projector image of frame ``index``: read-only ``uint8`` array ``(height, width)``.

        Patterns are rendered once and kept in a small cache; flat frames are shared.
        """
        segment = self.segment_at(index)
        if segment.kind == "patterns":
            pattern_index = self.pattern_index_at(index)
            if pattern_index is not None:
                return self.pattern_image(pattern_index)
            return self._flat(0)
        if segment.kind in ("start_code", "end_code"):
            code = self.start_code if segment.kind == "start_code" else self.end_code
            return self._flat(int(code.frame_levels()[index - code.first_frame]))
        return self._flat(1 if segment.kind == "white" else 0)

    def pattern_image(self, pattern_index: int) -> np.ndarray:
        """Projector image of one pattern (read-only ``uint8``, cached)."""
        if not 0 <= pattern_index < len(self.patterns):
            raise IndexError(f"pattern {pattern_index} outside 0..{len(self.patterns) - 1}")
        return self._cache(pattern_index)

    def _render_pattern(self, pattern_index: int) -> np.ndarray:
        pattern = self.patterns[pattern_index]
        width, height = self.projector
        canvas = np.ones((height, width), dtype=np.float32)  # drawn black on white
        for marker in self.markers_shown(pattern_index):
            draw_cells(canvas, self._marker_cells(int(marker)), self.centres[pattern.array, marker],
                       pattern.marker_side_px)
        image = np.rint(canvas * 255.0).astype(np.uint8)
        if self.markers.inverted:
            np.subtract(255, image, out=image)
        image.flags.writeable = False
        return image

    def _marker_cells(self, marker_id: int) -> np.ndarray:
        if marker_id not in self._bits:
            self._bits[marker_id] = marker_bits(self.markers.spec, marker_id).astype(np.float64)
        return self._bits[marker_id]

    def _flat(self, level: int) -> np.ndarray:
        """All-white (1) or all-black (0) frame, made once per sequence."""
        if level not in self._flats:
            width, height = self.projector
            image = np.full((height, width), 255 if level else 0, dtype=np.uint8)
            image.flags.writeable = False
            self._flats[level] = image
        return self._flats[level]

    def core(self) -> Any:
        """The sequence as the C++ core holds it (``_core.ingest.Sequence``): read and
        checked once, then kept for every camera's ingest. A sequence is not changed once
        built, so the kept one stays its twin."""
        if self._core_sequence is None:
            from calibproj import _core

            self._core_sequence = _core.ingest.Sequence(self.to_dict())
        return self._core_sequence

    # ------------------------------------------------------------------- files

    def to_dict(self) -> dict[str, Any]:
        """The body of ``sequence.json`` (without the schema tag)."""
        layout = self.layout
        whites = [s for s in self.segments if s.kind == "white"]
        blacks = [s for s in self.segments if s.kind == "black"]
        return {
            "markers": {
                "spec": self.markers.spec, "system": self.markers.system, "family": self.markers.family,
                "grid_cells": self.markers.grid_cells, "quad_cells": self.markers.quad_cells,
                "id_count": self.markers.id_count, "inverted": self.markers.inverted,
            },
            "projector": {"resolution": list(self.projector), "fps": self.fps},
            "layout": {
                "grid": list(layout.grid), "arrays": layout.arrays, "scales": list(layout.scales),
                "marker_px": layout.marker_px, "margin_px": layout.margin, "snap_to_pixels": layout.snap_to_pixels,
                "min_gap_modules": self.min_gap_modules, "order": "array-major",
            },
            "frames_per_pattern": self.frames_per_pattern,
            "frame_count": self.frame_count,
            "duration_s": self.duration_s,
            "centres": self.centres.tolist(),
            "scales": [
                {"scale": scale, "marker_side_px": layout.marker_side(scale),
                 "module_px": layout.marker_side(scale) / self.markers.grid_cells}
                for scale in layout.scales
            ],
            "patterns": [
                {"array": p.array, "scale_index": p.scale_index, "scale": p.scale,
                 "marker_side_px": p.marker_side_px, "first_frame": p.first_frame,
                 "last_frame": p.last_frame, "omitted": list(p.omitted)}
                for p in self.patterns
            ],
            "codes": {"start": self.start_code.to_dict(), "end": self.end_code.to_dict()},
            "reference_frames": {
                "white": [{"first_frame": s.first_frame, "last_frame": s.last_frame} for s in whites],
                "black": [{"first_frame": s.first_frame, "last_frame": s.last_frame} for s in blacks],
            },
            "segments": [{"kind": s.kind, "first_frame": s.first_frame, "last_frame": s.last_frame}
                         for s in self.segments],
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Sequence:
        """Build from the body of ``sequence.json`` (structure checked beforehand)."""
        markers, layout = data["markers"], data["layout"]
        return cls(
            markers=MarkerSystem(
                spec=markers["spec"], system=markers["system"], family=markers["family"],
                grid_cells=int(markers["grid_cells"]), quad_cells=int(markers["quad_cells"]),
                id_count=int(markers.get("id_count", 0)), inverted=bool(markers["inverted"]),
            ),
            projector=tuple(int(v) for v in data["projector"]["resolution"]),
            fps=float(data["projector"]["fps"]),
            layout=MsmLayout(
                projector=tuple(int(v) for v in data["projector"]["resolution"]),
                grid=tuple(int(v) for v in layout["grid"]), arrays=int(layout["arrays"]),
                scales=tuple(float(v) for v in layout["scales"]), marker_px=float(layout["marker_px"]),
                margin_px=float(layout["margin_px"]), snap_to_pixels=bool(layout["snap_to_pixels"]),
            ),
            min_gap_modules=float(layout["min_gap_modules"]),
            frames_per_pattern=int(data["frames_per_pattern"]),
            centres=np.asarray(data["centres"], dtype=np.float64),
            patterns=[
                Pattern(int(p["array"]), int(p["scale_index"]), float(p["scale"]), float(p["marker_side_px"]),
                        int(p["first_frame"]), int(p["last_frame"]), tuple(int(m) for m in p["omitted"]))
                for p in data["patterns"]
            ],
            segments=[Segment(s["kind"], int(s["first_frame"]), int(s["last_frame"])) for s in data["segments"]],
            start_code=LightCode.from_dict(data["codes"]["start"]),
            end_code=LightCode.from_dict(data["codes"]["end"]),
        )

    def save(self, path: str | os.PathLike) -> None:
        """Write ``sequence.json`` atomically (after :meth:`validate`)."""
        self.validate()
        write_json(path, KIND, MAJOR, self.to_dict())

    @classmethod
    def load(cls, path: str | os.PathLike) -> Sequence:
        """Read and check a ``sequence.json``; :class:`FormatError` (a ValueError) naming
        the file for another kind of file, a newer schema or inconsistent content.

        The C++ core reads and checks the file (the one reader of the format, which
        ``calibproj-native`` uses too), so both tools accept exactly the same files.
        """
        from calibproj import _core

        try:
            document = _core.formats.read_sequence(Path(path))
        except ValueError as error:
            raise FormatError(str(error)) from None
        return cls.from_dict(document)

    # --------------------------------------------------------------- validation

    def validate(self) -> None:
        """Raise ValueError if the parts of the sequence disagree with each other: the
        C++ core's one reader of the format checks it (and keeps it for the ingest)."""
        self._core_sequence = None
        try:
            self.core()
        except (TypeError, ValueError) as error:
            raise ValueError(str(error).removeprefix("sequence: ")) from None


