"""Ground truth of a simulation: ``truth.json`` (``calibproj.truth/1``).

Cameras are written like ``camera_poses.json`` (``R``, ``t``, ``center``) so that
``calibproj.formats.poses.read_poses`` reads both, plus what a test needs to check a
calibration end to end::

    {"schema": "calibproj.truth/1", "unit": "m", "frame": "floor",
     "cameras": {name: {"R", "t", "center", "K", "dist", "resolution", "fps", "start_offset_s"}},
     "plane": {"normal": [0, 0, 1], "offset": 0.0},          # normal . X = offset
     "projector": {"R", "t", "center", "K", "resolution"},
     "points": {"markers_per_array": 32, "ids": [...], "xyz": [[x, y, z], ...]},
     "eval_points": {"ids": [...], "xyz": [...]},
     ...}                                                    # extra fields of the simulator
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from calibproj.formats.jsonio import write_json
from calibproj.formats.poses import SCHEMA_MAJOR, TRUTH_KIND, pose_json
from calibproj.simulate.scene import Scene


def truth_document(
    scene: Scene,
    points: tuple[np.ndarray, np.ndarray],
    markers_per_array: int | None,
    eval_points: tuple[np.ndarray, np.ndarray] | None = None,
    extra: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Body of ``truth.json``; ``points`` and ``eval_points`` are ``(ids (N,), xyz (N, 3))``."""
    cameras = {}
    for camera in scene.cameras:
        cameras[camera.name] = {
            **pose_json(camera.R, camera.t),
            "K": camera.K.tolist(),
            "dist": list(camera.dist),
            "resolution": list(camera.resolution),
            "fps": camera.fps,
            "start_offset_s": camera.start_offset_s,
        }
    projector = scene.projector
    body: dict[str, Any] = {
        "unit": "m",
        "frame": "floor",
        "cameras": cameras,
        "plane": {"normal": [0.0, 0.0, 1.0], "offset": 0.0},
        "projector": {**pose_json(projector.R, projector.t), "K": projector.K.tolist(),
                      "resolution": list(projector.resolution)},
        "points": {"markers_per_array": markers_per_array, **_points_json(*points)},
    }
    if eval_points is not None:
        body["eval_points"] = _points_json(*eval_points)
    if scene.boxes:
        body["surfaces"] = _surfaces_json(scene)
    body.update(extra or {})
    return body


def write_truth(path: str | os.PathLike, body: dict[str, Any]) -> None:
    """Write ``truth.json`` atomically from ``truth_document(...)``."""
    write_json(path, TRUTH_KIND, SCHEMA_MAJOR, body)


def _surfaces_json(scene: Scene) -> dict[str, Any]:
    """The planes the projection may land on: surface number -> name and plane."""
    from calibproj.simulate import boxes

    count = 1 + len(boxes.FACES) * len(scene.boxes)
    out = {}
    for surface in range(count):
        normal, offset = boxes.surface_plane(scene.boxes, surface)
        out[str(surface)] = {"name": boxes.surface_name(surface), "normal": normal.tolist(), "offset": offset}
    return out


def _points_json(ids: np.ndarray, xyz: np.ndarray) -> dict[str, Any]:
    return {"ids": np.asarray(ids, dtype=np.int64).tolist(), "xyz": np.asarray(xyz, dtype=float).tolist()}
