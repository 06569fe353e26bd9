"""Rays and the room's surfaces: the floor (z = 0, or its relief) and the faces of the
boxes on it.

The projector's light lands on the first surface its ray meets (a table top rather
than the floor beneath it, which lies in the table's shadow); a camera sees a point
only when no box stands between them.

Surfaces are numbered: ``FLOOR`` (0) is the floor; box ``k``'s faces are
``1 + 6 k + f`` with ``f`` one of ``FACES`` (its top, underside and the four sides).
Each surface is part of a plane ``n . X = d`` (``surface_plane``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from calibproj.simulate.scene import Box, Floor

FLOOR = 0
FACES = ("top", "bottom", "-x", "+x", "-y", "+y")
# A hit closer than this to the ray's end (metres) does not hide the end point itself.
EPSILON_M = 1e-6


def surface_of(box: int, face: str) -> int:
    return 1 + 6 * box + FACES.index(face)


def surface_name(surface: int) -> str:
    if surface == FLOOR:
        return "floor"
    box, face = divmod(surface - 1, 6)
    return f"box {box} {FACES[face]}"


def surface_plane(boxes: Sequence[Box], surface: int) -> tuple[np.ndarray, float]:
    """``(n, d)``: the unit normal (pointing out of the box, up for the floor) and
    offset of the plane ``n . X = d`` the surface lies on."""
    if surface == FLOOR:
        return np.array([0.0, 0.0, 1.0]), 0.0
    box_index, face = divmod(surface - 1, 6)
    box = boxes[box_index]
    axis = (2, 2, 0, 0, 1, 1)[face]
    outward = 1.0 if face in (0, 3, 5) else -1.0
    n = np.zeros(3)
    n[axis] = outward
    value = box.upper[axis] if outward > 0 else box.lower[axis]
    return n, float(outward * value)


def first_hits(origin: np.ndarray, directions: np.ndarray, boxes: Sequence[Box],
               floor: Floor | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Where rays from ``origin`` first meet a surface: ``(points (N, 3), surfaces (N,))``;
    NaN and -1 for rays that meet none (going up, or past the floor never). The floor is
    ``floor`` with its relief, or the plane z = 0 without one."""
    origin = np.asarray(origin, dtype=float)
    directions = np.asarray(directions, dtype=float).reshape(-1, 3)
    t = (floor or Floor()).ray_depths(origin, directions)
    t = np.where(t > 0, t, np.inf)
    surface = np.where(np.isfinite(t), FLOOR, -1)
    for k, box in enumerate(boxes):
        t_box, face = _enter(origin, directions, box)
        closer = t_box < t
        t = np.where(closer, t_box, t)
        surface = np.where(closer, 1 + 6 * k + face, surface)
    points = origin + np.where(np.isfinite(t), t, np.nan)[:, None] * directions
    return points, surface


def hidden(viewpoint: np.ndarray, points: np.ndarray, boxes: Sequence[Box]) -> np.ndarray:
    """Per point, whether a box stands between it and ``viewpoint`` (a point on a
    box's face is not hidden by that face itself)."""
    viewpoint = np.asarray(viewpoint, dtype=float)
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    directions = points - viewpoint
    length = np.linalg.norm(directions, axis=1)
    out = np.zeros(len(points), dtype=bool)
    for box in boxes:
        t_box, _ = _enter(viewpoint, directions, box)
        out |= t_box < 1.0 - EPSILON_M / np.maximum(length, EPSILON_M)
    return out


def inside(points: np.ndarray, boxes: Sequence[Box]) -> np.ndarray:
    """Per point, whether it lies inside a box."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    out = np.zeros(len(points), dtype=bool)
    for box in boxes:
        out |= np.all((points > box.lower) & (points < box.upper), axis=1)
    return out


def _enter(origin: np.ndarray, directions: np.ndarray, box: Box) -> tuple[np.ndarray, np.ndarray]:
    """Ray parameter at which each ray enters the box (inf when it misses it or starts
    inside it) and the face it enters through (an index into ``FACES``)."""
    lower, upper = box.lower, box.upper
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lower - origin) / directions
        t2 = (upper - origin) / directions
    parallel = directions == 0
    within = (origin >= lower) & (origin <= upper)
    # A ray parallel to a slab is inside it for every t, or for none.
    t1 = np.where(parallel, np.where(within, -np.inf, np.inf), t1)
    t2 = np.where(parallel, np.where(within, np.inf, -np.inf), t2)
    near, far = np.minimum(t1, t2), np.maximum(t1, t2)
    t_enter, t_exit = near.max(axis=1), far.min(axis=1)
    axis = near.argmax(axis=1)
    hit = (t_exit >= t_enter) & (t_enter > 0)
    positive = directions[np.arange(len(directions)), axis] > 0
    # Entering along +axis goes through the face facing -axis, and the other way round.
    face = np.where(axis == 2, np.where(positive, 1, 0), np.where(axis == 0, np.where(positive, 2, 3),
                                                                  np.where(positive, 4, 5)))
    return np.where(hit, t_enter, np.inf), face
