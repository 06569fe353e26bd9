"""Tracks: which cameras saw which point, and where (undistorted pixels).

``Tracks`` is the core's type (``calibproj._core.formats.Tracks``), the one the
registration, the self-calibration, the check and ``calibproj-native`` share; its
arrays are read-only views of the core's memory. A point is one projected MSM,
identified by ``(array, marker)`` with point id ``array * markers_per_array + marker``
(docs/conventions.md), or, for evaluation data, any non-negative integer id
(``markers_per_array`` is then ``None``).

Observations are stored flat, one row per (camera, point), ordered by camera then
point id: ``camera_index`` into ``camera_names``, ``point_index`` into ``point_ids``,
and ``xy``, the undistorted pixel position in that camera. That is what a bundle
adjuster takes.

File format (``calibproj.tracks/1``)::

    {"schema": "calibproj.tracks/1",
     "markers_per_array": 32,              # null for generic point ids
     "undistorted": true,                  # xy are undistorted pixels (same K)
     "cameras": ["far1", ...],             # every camera, even one that saw nothing
     "observations": {"far1": {"point_ids": [...], "xy": [[x, y], ...]}, ...}}
"""

from __future__ import annotations

import numpy as np

from calibproj import _core

Tracks = _core.formats.Tracks


def msm_point_ids(arrays: np.ndarray, markers: np.ndarray, markers_per_array: int) -> np.ndarray:
    """Point ids of MSMs ``(array, marker)``: ``array * markers_per_array + marker``."""
    arrays, markers = np.asarray(arrays, dtype=np.int64), np.asarray(markers, dtype=np.int64)
    if np.any((markers < 0) | (markers >= markers_per_array)) or np.any(arrays < 0):
        raise ValueError(f"MSM keys out of range: arrays >= 0 and markers in [0, {markers_per_array})")
    return arrays * markers_per_array + markers
