"""People walking through the room: what they hide from a camera and the shadow they cast.

A person is a vertical cylinder (``Person``) moving along a straight line on the floor.
For each camera pixel that sees the floor, the ray from the camera to that floor point
is tested against the cylinder (the person hides the floor behind) and so is the ray
from the projector to the same floor point (the person's shadow: no projected light,
room light only). Where a camera sees a person, the point of the body it sees (on the
side or the top of the cylinder) is lit by the room and by the projector's content at
that point, with the cosine of the light's incidence on the body relative to the
floor's: markers landing on a person are drawn there, distorted and off the floor, as
a real camera sees them (the ingest's floor check must drop them). A body's side facing
away from the projector gets room light only; one person's shadow on another is not
drawn.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np


def blocked(origin: np.ndarray, floor_x: np.ndarray, floor_y: np.ndarray, axis_xy: np.ndarray, radius_m: float,
            height_m: float) -> np.ndarray:
    """Where the segment from ``origin`` (x, y, z above the floor) to each floor point
    passes through the vertical cylinder of ``radius_m`` and ``height_m`` standing on
    ``axis_xy``. NaN floor points are never blocked."""
    u_x, u_y = floor_x - origin[0], floor_y - origin[1]
    w_x, w_y = axis_xy[0] - origin[0], axis_xy[1] - origin[1]
    # Along the segment (s = 0 at the origin, 1 on the floor) the height is
    # origin_z (1 - s): only s >= 1 - height / origin_z is low enough to meet the person.
    lowest = max(0.0, 1.0 - height_m / origin[2]) if origin[2] > 0 else 0.0
    length2 = u_x * u_x + u_y * u_y
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.clip((w_x * u_x + w_y * u_y) / length2, lowest, 1.0)
    s = np.where(length2 > 0, s, 1.0)
    d_x, d_y = origin[0] + s * u_x - axis_xy[0], origin[1] + s * u_y - axis_xy[1]
    with np.errstate(invalid="ignore"):
        return d_x * d_x + d_y * d_y <= radius_m * radius_m


def surface_points(origin: np.ndarray, floor_points: np.ndarray, axis_xy: np.ndarray, radius_m: float,
                   height_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Where the segments from ``origin`` to ``floor_points`` (``(N, 2)``, on z = 0) first
    meet the cylinder, and the body's outward normal there: ``(points (N, 3), normals
    (N, 3))``. The segments are ones that do meet it (``blocked``)."""
    u = np.column_stack([floor_points - origin[:2], np.full(len(floor_points), -origin[2])])
    offset = origin[:2] - axis_xy
    a = np.einsum("ij,ij->i", u[:, :2], u[:, :2])
    b = 2.0 * (u[:, :2] @ offset)
    c = float(offset @ offset) - radius_m * radius_m
    with np.errstate(invalid="ignore", divide="ignore"):
        side = (-b - np.sqrt(np.maximum(b * b - 4.0 * a * c, 0.0))) / (2.0 * a)
    side = np.where(a > 0, np.clip(side, 0.0, 1.0), 1.0)
    # Entering above the head: the ray comes in through the top.
    top = max(0.0, 1.0 - height_m / origin[2]) if origin[2] > height_m else 0.0
    through_top = origin[2] * (1.0 - side) > height_m
    s = np.where(through_top, top, side)
    points = origin + s[:, None] * u
    normals = np.zeros_like(points)
    normals[through_top, 2] = 1.0
    radial = points[~through_top, :2] - axis_xy
    normals[~through_top, :2] = radial / np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-12)
    return points, normals


@dataclass(frozen=True, eq=False)  # numpy fields
class ProjectorLight:
    """The projector as a pinhole (world-to-projector ``R``, ``t``, matrix ``K``) and
    its content: ``image(key)`` gives a content's projector image (``uint8``)."""

    position: np.ndarray
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    resolution: tuple[int, int]
    image: Callable[[object], np.ndarray]

    def light(self, points: np.ndarray, normals: np.ndarray, weights: Mapping[object, float | np.ndarray],
              rows: np.ndarray) -> np.ndarray:
        """Projected light (0..1 of full white, times the incidence cosine relative to
        the floor's) at world points with outward normals; ``weights`` per content as the
        camera's exposure saw them (a float, or per image row: ``rows`` says each point's)."""
        toward = self.position - points
        toward /= np.linalg.norm(toward, axis=1, keepdims=True)
        facing = np.einsum("ij,ij->i", normals, toward)
        with np.errstate(invalid="ignore", divide="ignore"):
            incidence = np.clip(facing / np.maximum(toward[:, 2], 1e-6), 0.0, 1.0)
        in_projector = points @ self.R.T + self.t
        pixels = in_projector @ self.K.T
        with np.errstate(invalid="ignore", divide="ignore"):
            column = np.rint(pixels[:, 0] / pixels[:, 2]).astype(np.int64, copy=False)
            row = np.rint(pixels[:, 1] / pixels[:, 2]).astype(np.int64, copy=False)
        width, height = self.resolution
        lit = (in_projector[:, 2] > 0) & (facing > 0) & (column >= 0) & (column < width) & (row >= 0) & (row < height)
        light = np.zeros(len(points))
        for key, weight in weights.items():
            share = np.ravel(weight)[rows[lit]] if isinstance(weight, np.ndarray) else weight
            light[lit] += share * self.image(key)[row[lit], column[lit]] / 255.0
        return light * incidence


class PeopleInView:
    """The people of a scene as one camera sees them, frame by frame."""

    def __init__(self, people: Sequence, camera_position: Sequence[float], projector: ProjectorLight,
                 floor_x: np.ndarray, floor_y: np.ndarray, vignetting: np.ndarray, ambient: float,
                 contrast: float) -> None:
        self.people = tuple(people)
        self.camera = np.asarray(camera_position, dtype=float)
        self.projector = projector
        self.floor_x, self.floor_y = floor_x, floor_y
        self.vignetting = vignetting
        self.ambient, self.contrast = ambient, contrast

    def apply(self, irradiance: np.ndarray, ambient_gain: np.ndarray, time_s: float,
              weights: Mapping[object, float | np.ndarray]) -> np.ndarray | None:
        """``irradiance`` with the people present at ``time_s`` (a new array), lit by the
        contents ``weights`` (as ``ProjectorLight.light`` takes them), or None when
        nobody is in the room then."""
        present = [(person, person.centre(time_s)) for person in self.people]
        present = [(person, centre) for person, centre in present if centre is not None]
        if not present:
            return None
        out = irradiance.copy()
        for person, centre in present:
            shadow = blocked(self.projector.position, self.floor_x, self.floor_y, centre, person.radius_m,
                             person.height_m)
            out[shadow] = ambient_gain[shadow]
        for person, centre in present:
            body = blocked(self.camera, self.floor_x, self.floor_y, centre, person.radius_m, person.height_m)
            rows, columns = np.nonzero(body)
            floor_points = np.column_stack([self.floor_x[rows, columns], self.floor_y[rows, columns]])
            points, normals = surface_points(self.camera, floor_points, centre, person.radius_m, person.height_m)
            light = self.projector.light(points, normals, weights, rows)
            lit = person.albedo * (self.ambient + self.contrast * light)
            out[rows, columns] = (self.vignetting[rows, columns] * lit).astype(out.dtype)
        return out
