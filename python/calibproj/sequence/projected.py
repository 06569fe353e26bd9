"""Where the projector draws the MSMs: every centre's projector pixel, the marker side
at scale 1 and, per MSM, the largest marker drawn at it, from a sequence or a layout.

The metric scale (a marker's printed size), the registration's projector model and the
densification read the projection's geometry from here.
"""

from __future__ import annotations

import os

from calibproj import _core
from calibproj.sequence.sequence import Sequence

# Where the projector draws the MSMs (the core's class): projector pixels of every MSM
# centre, the marker side at scale 1, the projector's size and per MSM the largest
# marker drawn at it; ``help(ProjectedMarkers)`` documents it.
ProjectedMarkers = _core.formats.ProjectedMarkers


def projected_markers(sequence) -> ProjectedMarkers:
    """The MSMs a ``calibproj.sequence.Sequence`` (what ``sequence.json`` holds) draws,
    with per MSM the side of the largest marker drawn at it (NaN where none)."""
    return ProjectedMarkers.from_sequence(sequence)


def layout_markers(layout) -> ProjectedMarkers:
    """The MSMs of a ``calibproj.sequence.MsmLayout`` (their largest sides not known)."""
    return ProjectedMarkers(layout.centres(), layout.marker_side(1.0), tuple(layout.projector))


def read_projected_markers(path: str | os.PathLike, markers_per_array: int | None = None) -> ProjectedMarkers:
    """The MSM geometry of a ``sequence.json``; with ``markers_per_array`` (the tracks'),
    checks that the sequence is the one the tracks were made from."""
    markers = projected_markers(Sequence.load(path))
    if markers_per_array is not None and markers_per_array != markers.markers_per_array:
        raise ValueError(f"{path}: {markers.markers_per_array} markers per array, but the tracks have "
                         f"{markers_per_array}; is it the sequence of these tracks?")
    return markers
