"""The projection sequence: what the projector shows in every frame, and its file.

A sequence is a timeline of contiguous segments (white and black reference frames,
the start light code, the MSM patterns, the end light code) at the projector's frame
rate. Each pattern shows one array of MSMs at one scale for ``frames_per_pattern``
frames; patterns are ordered array-major (array 0 at every scale, then array 1, ...).
``sequence.json`` (``calibproj.sequence/1``) holds everything needed to decode a
recording: marker family and colours, projector resolution and frame rate, layout
parameters, every marker centre (per array, the same at every scale), the frames of
every pattern and segment, and the light codes.

The data model is the C++ core's (``calibproj._core.ingest.Sequence``, with its parts
``MarkerSystem``, ``Pattern``, ``Segment`` and ``_core.sync.LightCode``): the core
checks a sequence once when it is built, reads and writes ``sequence.json``, and gives
it to every camera's ingest. :class:`Sequence` adds what only Python does with it:
the projector images of its frames.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Any

import numpy as np

from calibproj import _core
from calibproj.formats.jsonio import FormatError
from calibproj.sequence.layout import MsmLayout
from calibproj.sequence.markers import marker_bits
from calibproj.sequence.raster import draw_cells

# Patterns kept rendered per sequence: consecutive frames mostly share one pattern, so
# a few suffice for renderers that walk the timeline (one 1080p pattern is 2 MB).
DEFAULT_PATTERN_CACHE = 8

# The parts of a sequence, as the core defines them.
MarkerSystem = _core.ingest.MarkerSystem
Pattern = _core.ingest.Pattern
Segment = _core.ingest.Segment


class Sequence(_core.ingest.Sequence):
    """A projection sequence with its rendering; build one with
    :func:`calibproj.sequence.build_sequence` or read one with :meth:`load`.

    Built from the keyword parts of ``_core.ingest.Sequence`` (``markers``,
    ``projector``, ``fps``, ``grid``, ``scales``, ``marker_px``, ``margin_px``,
    ``snap_to_pixels``, ``min_gap_modules``, ``frames_per_pattern``, ``centres``,
    ``patterns``, ``segments``, ``start_code``, ``end_code``) or from another sequence;
    ValueError naming the first part that disagrees with the others. A sequence is not
    changed once built.
    """

    def __init__(self, *args: Any, pattern_cache_size: int = DEFAULT_PATTERN_CACHE, **parts: Any) -> None:
        try:
            super().__init__(*args, **parts)
        except ValueError as error:
            raise ValueError(str(error).removeprefix("sequence: ")) from None
        # The core gives a new list on every read; the sequence does not change, so once.
        self._patterns = tuple(super().patterns)
        self._segments = tuple(super().segments)
        self._cache = functools.lru_cache(maxsize=pattern_cache_size)(self._render_pattern)
        self._bits: dict[int, np.ndarray] = {}
        self._flats: dict[int, np.ndarray] = {}

    @property
    def patterns(self) -> tuple[Pattern, ...]:
        """Every :class:`Pattern`, in time order."""
        return self._patterns

    @property
    def segments(self) -> tuple[Segment, ...]:
        """The :class:`Segment` s that tile the frames."""
        return self._segments

    def parts(self) -> dict[str, Any]:
        """The keyword parts the sequence is built from."""
        return {"markers": self.markers, "projector": self.projector, "fps": self.fps, "grid": self.grid,
                "scales": self.scales, "marker_px": self.marker_px, "margin_px": self.margin_px,
                "snap_to_pixels": self.snap_to_pixels, "min_gap_modules": self.min_gap_modules,
                "frames_per_pattern": self.frames_per_pattern, "centres": self.centres,
                "patterns": list(self._patterns), "segments": list(self._segments), "start_code": self.start_code,
                "end_code": self.end_code}

    def replaced(self, **changes: Any) -> Sequence:
        """A sequence with some parts changed (checked as any: ValueError)."""
        return Sequence(**{**self.parts(), **changes})

    @functools.cached_property
    def layout(self) -> MsmLayout:
        """The layout the centres were placed by (for plans of further arrays)."""
        return MsmLayout(projector=self.projector, grid=self.grid, arrays=self.arrays, scales=self.scales,
                         marker_px=self.marker_px, margin_px=self.margin_px, snap_to_pixels=self.snap_to_pixels)

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
        if not 0 <= pattern_index < len(self._patterns):
            raise IndexError(f"pattern {pattern_index} outside 0..{len(self._patterns) - 1}")
        return self._cache(pattern_index)

    def _render_pattern(self, pattern_index: int) -> np.ndarray:
        pattern = self._patterns[pattern_index]
        width, height = self.projector
        centres = self.centres
        canvas = np.ones((height, width), dtype=np.float32)  # drawn black on white
        for marker in self.markers_shown(pattern_index):
            draw_cells(canvas, self._marker_cells(int(marker)), centres[pattern.array, marker],
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

    # ------------------------------------------------------------------- files

    @classmethod
    def load(cls, path: str | os.PathLike) -> Sequence:
        """Read and check a ``sequence.json``; :class:`FormatError` (a ValueError) naming
        the file for another kind of file, a newer schema or inconsistent content.

        The C++ core reads and checks the file (the one reader of the format, which
        ``calibproj-native`` uses too), so both tools accept exactly the same files.
        """
        try:
            return cls(_core.formats.read_sequence(Path(path)))
        except ValueError as error:
            raise FormatError(str(error)) from None
