"""People walking through the room: what they hide from a camera and the shadow they cast.

A person is a vertical cylinder (``Person``) moving along a straight line on the floor.
For each camera pixel that sees the floor, the ray from the camera to that floor point
is tested against the cylinder (the person hides the floor behind) and so is the ray
from the projector to the same floor point (the person's shadow: no projected light,
room light only). A person is lit by the room and by the projector's mean light, not
by its patterns: markers landing on a person are not drawn, only lost.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

# Share of the projector's full white that falls on a person on average (patterns are
# mostly dark between the markers).
PERSON_PROJECTOR_LIGHT = 0.2


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


class PeopleInView:
    """The people of a scene as one camera sees them, frame by frame."""

    def __init__(self, people: Sequence, camera_position: Sequence[float], projector_position: Sequence[float],
                 floor_x: np.ndarray, floor_y: np.ndarray, vignetting: np.ndarray, ambient: float,
                 contrast: float) -> None:
        self.people = tuple(people)
        self.camera = np.asarray(camera_position, dtype=float)
        self.projector = np.asarray(projector_position, dtype=float)
        self.floor_x, self.floor_y = floor_x, floor_y
        self.vignetting = vignetting
        self.ambient, self.contrast = ambient, contrast

    def apply(self, irradiance: np.ndarray, ambient_gain: np.ndarray, time_s: float) -> np.ndarray | None:
        """``irradiance`` with the people present at ``time_s`` (a new array), or None
        when nobody is in the room then."""
        present = [(person, person.centre(time_s)) for person in self.people]
        present = [(person, centre) for person, centre in present if centre is not None]
        if not present:
            return None
        out = irradiance.copy()
        for person, centre in present:
            shadow = blocked(self.projector, self.floor_x, self.floor_y, centre, person.radius_m, person.height_m)
            out[shadow] = ambient_gain[shadow]
        for person, centre in present:
            body = blocked(self.camera, self.floor_x, self.floor_y, centre, person.radius_m, person.height_m)
            lit = person.albedo * (self.ambient + self.contrast * PERSON_PROJECTOR_LIGHT)
            out[body] = (self.vignetting[body] * lit).astype(out.dtype)
        return out
