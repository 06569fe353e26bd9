"""Tracks: which cameras saw which point, and where (undistorted pixels).

A point is one projected MSM, identified by ``(array, marker)`` with point id
``array * markers_per_array + marker`` (docs/conventions.md), or, for evaluation
data, any non-negative integer id (``markers_per_array`` is then ``None``).

Observations are stored flat, one row per (camera, point): ``camera_index`` into
``camera_names``, ``point_index`` into ``point_ids``, and ``xy``, the undistorted
pixel position in that camera. That is what a bundle adjuster takes.

File format (``calibproj.tracks/1``)::

    {"schema": "calibproj.tracks/1",
     "markers_per_array": 32,              # null for generic point ids
     "undistorted": true,                  # xy are undistorted pixels (same K)
     "cameras": ["far1", ...],             # every camera, even one that saw nothing
     "observations": {"far1": {"point_ids": [...], "xy": [[x, y], ...]}, ...}}
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibproj.io.json_values import describe
from calibproj.io.jsonio import FormatError

MAX_INT32 = 2**31 - 1  # markers_per_array is an int in the C++ core


@dataclass(frozen=True, eq=False)  # numpy fields: compare the arrays explicitly
class Tracks:
    """Observations of points by cameras, numpy-backed.

    Build with ``Tracks.from_observations``; the constructor expects arrays that are
    already consistent (sorted by camera then point, no duplicates).
    """

    camera_names: tuple[str, ...]
    point_ids: np.ndarray  # (P,) int64, sorted, unique
    camera_index: np.ndarray  # (M,) int32 into camera_names
    point_index: np.ndarray  # (M,) int32 into point_ids
    xy: np.ndarray  # (M, 2) float64 undistorted pixels
    markers_per_array: int | None = None

    @classmethod
    def from_observations(
        cls,
        camera_names: Sequence[str],
        cameras: Iterable[int] | Iterable[str] | np.ndarray,
        point_ids: Iterable[int] | np.ndarray,
        xy: np.ndarray,
        markers_per_array: int | None = None,
    ) -> Tracks:
        """Tracks from one row per observation.

        Args:
            camera_names: all cameras, in order (a camera may have no observation).
            cameras: per observation, the camera's index into ``camera_names`` or its name.
            point_ids: per observation, the point id.
            xy: per observation, undistorted pixels, shape ``(M, 2)``.
            markers_per_array: markers per MSM array when ids are ``(array, marker)`` keys.
        """
        camera_names = tuple(camera_names)
        if len(set(camera_names)) != len(camera_names):
            raise ValueError(f"duplicate camera names in {list(camera_names)}")
        camera_index = _camera_indices(camera_names, cameras)
        ids = np.asarray(point_ids, dtype=np.int64).ravel()
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if not len(camera_index) == len(ids) == len(xy):
            raise ValueError(
                f"observation arrays differ in length: {len(camera_index)} cameras, {len(ids)} ids, {len(xy)} xy"
            )
        if len(ids) and ids.min() < 0:
            raise ValueError("point ids must be non-negative")
        if not np.all(np.isfinite(xy)):
            raise ValueError("observations must be finite")
        order = np.lexsort((ids, camera_index))
        camera_index, ids, xy = camera_index[order], ids[order], xy[order]
        duplicate = (np.diff(camera_index) == 0) & (np.diff(ids) == 0)
        if np.any(duplicate):
            first = int(np.argmax(duplicate))
            raise ValueError(f"camera {camera_names[camera_index[first]]!r} observes point {ids[first]} twice")
        unique_ids, point_index = np.unique(ids, return_inverse=True)
        return cls(
            camera_names, unique_ids, camera_index.astype(np.int32), point_index.astype(np.int32).ravel(), xy,
            _check_markers_per_array(markers_per_array),
        )

    @classmethod
    def empty(cls, camera_names: Sequence[str], markers_per_array: int | None = None) -> Tracks:
        return cls.from_observations(camera_names, [], [], np.zeros((0, 2)), markers_per_array)

    # -- sizes and statistics ---------------------------------------------------------

    def __len__(self) -> int:
        """Number of observations."""
        return len(self.xy)

    @property
    def num_cameras(self) -> int:
        return len(self.camera_names)

    @property
    def num_points(self) -> int:
        return len(self.point_ids)

    @property
    def keys(self) -> np.ndarray:
        """``(array, marker)`` of every point, shape ``(P, 2)``; needs ``markers_per_array``."""
        if self.markers_per_array is None:
            raise ValueError("these tracks use generic point ids, not (array, marker) keys")
        return np.column_stack(np.divmod(self.point_ids, self.markers_per_array))

    def observation_ids(self) -> np.ndarray:
        """Point id of every observation, shape ``(M,)``."""
        return self.point_ids[self.point_index]

    def counts_per_camera(self) -> dict[str, int]:
        counts = np.bincount(self.camera_index, minlength=self.num_cameras)
        return dict(zip(self.camera_names, counts.tolist()))

    def track_lengths(self) -> np.ndarray:
        """Number of cameras that saw each point, shape ``(P,)``."""
        return np.bincount(self.point_index, minlength=self.num_points)

    def visibility(self) -> np.ndarray:
        """Boolean matrix ``(P, C)``: point p seen by camera c."""
        seen = np.zeros((self.num_points, self.num_cameras), dtype=bool)
        seen[self.point_index, self.camera_index] = True
        return seen

    def pair_counts(self) -> np.ndarray:
        """Points shared by every pair of cameras, ``(C, C)``; the diagonal is per-camera counts."""
        seen = self.visibility().astype(np.int64)
        return seen.T @ seen

    def pair_counts_by_name(self) -> dict[tuple[str, str], int]:
        """Shared points of every camera pair ``(a, b)`` with a before b, zeros included."""
        counts = self.pair_counts()
        names = self.camera_names
        return {
            (names[a], names[b]): int(counts[a, b])
            for a in range(self.num_cameras)
            for b in range(a + 1, self.num_cameras)
        }

    # -- access and filtering ---------------------------------------------------------

    def observations(self, camera: str) -> tuple[np.ndarray, np.ndarray]:
        """Point ids and undistorted pixels seen by one camera."""
        mask = self.camera_index == self._camera_position(camera)
        return self.point_ids[self.point_index[mask]], self.xy[mask]

    def bundle_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(camera_index int32 (M,), point_index int32 (M,), xy float64 (M, 2))``."""
        return self.camera_index, self.point_index, self.xy

    def select(self, observation_mask: np.ndarray, camera_names: Sequence[str] | None = None) -> Tracks:
        """The observations where the mask is true; cameras kept (or restricted to ``camera_names``)."""
        observation_mask = np.asarray(observation_mask, dtype=bool)
        names = self.camera_names if camera_names is None else tuple(camera_names)
        old_to_new = {old: names.index(name) for old, name in enumerate(self.camera_names) if name in names}
        keep = observation_mask & np.isin(self.camera_index, list(old_to_new))
        remap = np.full(self.num_cameras, -1, dtype=np.int32)
        for old, new in old_to_new.items():
            remap[old] = new
        return Tracks.from_observations(
            names, remap[self.camera_index[keep]], self.point_ids[self.point_index[keep]], self.xy[keep],
            self.markers_per_array,
        )

    def drop_cameras(self, names: Iterable[str]) -> Tracks:
        """Without the named cameras (and their observations)."""
        drop = set(names)
        unknown = drop - set(self.camera_names)
        if unknown:
            raise ValueError(f"unknown camera(s) {sorted(unknown)}")
        return self.select(np.ones(len(self), dtype=bool), [n for n in self.camera_names if n not in drop])

    def keep_cameras(self, names: Sequence[str]) -> Tracks:
        """Only the named cameras, in the given order."""
        unknown = set(names) - set(self.camera_names)
        if unknown:
            raise ValueError(f"unknown camera(s) {sorted(unknown)}")
        return self.select(np.ones(len(self), dtype=bool), names)

    def drop_points(self, point_ids: Iterable[int]) -> Tracks:
        """Without the observations of the given point ids."""
        drop = np.isin(self.point_ids, np.fromiter(point_ids, dtype=np.int64))
        return self.select(~drop[self.point_index])

    def with_min_track_length(self, min_cameras: int = 2) -> Tracks:
        """Only the points seen by at least ``min_cameras`` cameras."""
        long_enough = self.track_lengths() >= min_cameras
        return self.select(long_enough[self.point_index])

    def _camera_position(self, camera: str) -> int:
        try:
            return self.camera_names.index(camera)
        except ValueError:
            raise KeyError(f"no camera {camera!r} in tracks (cameras: {', '.join(self.camera_names)})") from None

    # -- files --------------------------------------------------------------------------

    def write(self, path: str | os.PathLike) -> None:
        """Write ``tracks.json`` atomically; each camera's arrays sit on one line each
        (by the C++ core, as ``calibproj-native detect`` writes it)."""
        from calibproj import _core

        _core.formats.write_tracks(Path(path), self)

    @classmethod
    def from_core(cls, core: Any) -> Tracks:
        """From the core's ``_core.formats.Tracks``."""
        return cls(camera_names=core.camera_names, point_ids=core.point_ids, camera_index=core.camera_index,
                   point_index=core.point_index, xy=core.xy, markers_per_array=core.markers_per_array)

    @classmethod
    def read(cls, path: str | os.PathLike) -> Tracks:
        """Read ``tracks.json`` (by the C++ core, as ``calibproj-native`` reads it); errors
        name the file and the problem."""
        from calibproj import _core

        try:
            return cls.from_core(_core.formats.read_tracks(Path(path)))
        except _core.formats.InputError as error:
            raise FormatError(str(error)) from None


def msm_point_ids(arrays: np.ndarray, markers: np.ndarray, markers_per_array: int) -> np.ndarray:
    """Point ids of MSMs ``(array, marker)``: ``array * markers_per_array + marker``."""
    arrays, markers = np.asarray(arrays, dtype=np.int64), np.asarray(markers, dtype=np.int64)
    if np.any((markers < 0) | (markers >= markers_per_array)) or np.any(arrays < 0):
        raise ValueError(f"MSM keys out of range: arrays >= 0 and markers in [0, {markers_per_array})")
    return arrays * markers_per_array + markers


def _concatenate(parts: list[np.ndarray], dtype: type) -> np.ndarray:
    return np.concatenate(parts).astype(dtype) if parts else np.zeros(0, dtype=dtype)


def _camera_indices(camera_names: tuple[str, ...], cameras: Any) -> np.ndarray:
    cameras = np.asarray(list(cameras) if not isinstance(cameras, np.ndarray) else cameras)
    if cameras.size == 0:
        return np.zeros(0, dtype=np.int32)
    if cameras.dtype.kind in "US":
        lookup = {name: i for i, name in enumerate(camera_names)}
        unknown = sorted(set(cameras.tolist()) - set(lookup))
        if unknown:
            raise ValueError(f"observations of unknown camera(s) {unknown}")
        return np.array([lookup[name] for name in cameras.tolist()], dtype=np.int32)
    index = cameras.astype(np.int64).ravel()
    if index.min() < 0 or index.max() >= len(camera_names):
        raise ValueError(f"camera index out of range [0, {len(camera_names)})")
    return index.astype(np.int32)


def _check_markers_per_array(markers_per_array: Any) -> int | None:
    if markers_per_array is None:
        return None
    integer = isinstance(markers_per_array, (int, np.integer)) and not isinstance(markers_per_array, bool)
    if not integer or not 0 < markers_per_array <= MAX_INT32:
        raise ValueError(f"markers_per_array must be a positive integer or null, got {describe(markers_per_array)}")
    return int(markers_per_array)
