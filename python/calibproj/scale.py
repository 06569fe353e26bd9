"""Metric scale: turn a calibration in arbitrary units into metres from one measurement.

A calibration from image correspondences alone is defined up to scale (its unit is
"arbitrary": the first registered camera stands at height 1). One length measured in
the room fixes it. Three kinds of measurement are understood, written as for the
``--scale`` option of ``calibproj calibrate``:

``camera-height:NAME=METRES``
    the height of camera NAME's optical centre above the floor.
``distance:CAM_A,CAM_B=METRES``
    the distance between the optical centres of two cameras.
``marker-size:[ARRAY/MARKER=]METRES``
    the side of one projected marker at scale 1, measured on the floor (the outer
    side of the drawn square, border included; the mean of its four sides if they
    differ). ARRAY/MARKER names the marker measured (its array in the sequence and
    its index in the array, which is the id drawn); without it, the marker nearest
    the centre of the projected image is meant. To measure more precisely, measure
    a marker at a larger scale and divide by that scale.

How ``marker-size`` is turned into a scale. The calibration holds the reconstructed
floor position of every MSM centre it saw, by point id; the sequence holds the
projector pixel of every MSM centre and the marker side in projector pixels. Over a
floor plane, projector pixels and floor positions are related by a homography, which
changes scale across the floor when the projector is tilted. So the scale is taken
locally: the reconstructed centres within ``radius`` marker sides (in projector
pixels) of the measured marker give a least-squares homography from projector pixels
to floor coordinates; the square of the marker at scale 1 is mapped through it and
its mean side length, in calibration units, is compared with the measured one. This
is the distances between neighbouring MSM centres (whose projector-pixel spacing the
sequence gives) turned into a local floor scale, with every neighbour contributing
and the perspective of the projector modelled.

Applying a scale multiplies every camera translation ``t`` (hence every centre
``C = -R^T t``), every point and the floor RMS by the same factor; rotations and
pixel errors do not change. The unit becomes ``"m"``.
"""

from __future__ import annotations

import dataclasses
import difflib
import logging
import math
import os
import re
from dataclasses import dataclass

import numpy as np

from calibproj.calibration import Calibration

logger = logging.getLogger(__name__)

FORMS = {
    "camera-height": "camera-height:NAME=METRES",
    "marker-size": "marker-size:[ARRAY/MARKER=]METRES",
    "distance": "distance:CAM_A,CAM_B=METRES",
}
KINDS = tuple(FORMS)
SYNTAX = ", ".join(FORMS.values())

# Neighbourhood of the measured marker used to fit the local floor homography, in
# marker sides at scale 1: wide enough that dozens of centres average the point
# noise out, narrow enough that a floor that is only piecewise planar still fits.
DEFAULT_MARKER_RADIUS_SIDES = 6.0
# A homography has 8 degrees of freedom; twice as many centres keep the fit stable.
MIN_MARKER_NEIGHBOURS = 16

# Corners of a square of side 1 centred on the origin, in the order they go round it.
UNIT_SQUARE = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])


@dataclass(frozen=True)
class ScaleMeasurement:
    """One length measured in the room.

    Attributes:
        kind: ``camera-height``, ``marker-size`` or ``distance``.
        metres: the measured length.
        cameras: the camera (camera-height) or the two cameras (distance).
        marker: ``(array, marker)`` of the marker measured (marker-size); ``None``
            means the marker nearest the centre of the projected image.
        text: the measurement as written, for messages.
    """

    kind: str
    metres: float
    cameras: tuple[str, ...] = ()
    marker: tuple[int, int] | None = None
    text: str = ""

    def __str__(self) -> str:
        return self.text or f"{self.kind}={self.metres:g} m"


@dataclass(frozen=True, eq=False)  # numpy field
class ProjectedMarkers:
    """Where the projector draws the MSMs: what ``marker-size`` needs from the sequence.

    Attributes:
        centres_px: projector pixels of every MSM centre, ``(arrays, markers_per_array, 2)``;
            the MSM ``(array, marker)`` has point id ``array * markers_per_array + marker``.
        marker_side_px: side of a marker at scale 1 in projector pixels, border included.
        projector: projector resolution ``(width, height)``.
    """

    centres_px: np.ndarray
    marker_side_px: float
    projector: tuple[int, int]

    def __post_init__(self) -> None:
        centres = np.asarray(self.centres_px, dtype=float)
        if centres.ndim != 3 or centres.shape[2] != 2 or centres.size == 0:
            raise ValueError(f"MSM centres must have shape (arrays, markers, 2), got {centres.shape}")
        if not self.marker_side_px > 0:
            raise ValueError(f"marker side must be positive, got {self.marker_side_px} px")
        object.__setattr__(self, "centres_px", centres)

    @classmethod
    def from_sequence(cls, sequence) -> ProjectedMarkers:
        """From a ``calibproj.sequence.Sequence`` (what ``sequence.json`` holds)."""
        return cls(sequence.centres, sequence.layout.marker_side(1.0), tuple(sequence.projector))

    @classmethod
    def from_layout(cls, layout) -> ProjectedMarkers:
        """From a ``calibproj.sequence.MsmLayout``."""
        return cls(layout.centres(), layout.marker_side(1.0), tuple(layout.projector))

    @property
    def markers_per_array(self) -> int:
        return self.centres_px.shape[1]

    @property
    def point_count(self) -> int:
        return self.centres_px.shape[0] * self.centres_px.shape[1]

    def pixels(self, point_ids: np.ndarray) -> np.ndarray:
        """Projector pixels of MSM point ids, ``(N, 2)``."""
        return self.centres_px.reshape(-1, 2)[np.asarray(point_ids, dtype=np.int64)]

    def image_centre(self) -> np.ndarray:
        width, height = self.projector
        return np.array([(width - 1) / 2.0, (height - 1) / 2.0])  # pixel centres on integers


def read_projected_markers(path: str | os.PathLike, markers_per_array: int | None = None) -> ProjectedMarkers:
    """The MSM geometry of a ``sequence.json``; with ``markers_per_array`` (the tracks'),
    checks that the sequence is the one the tracks were made from."""
    from calibproj.sequence.sequence import Sequence

    markers = ProjectedMarkers.from_sequence(Sequence.load(path))
    if markers_per_array is not None and markers_per_array != markers.markers_per_array:
        raise ValueError(f"{path}: {markers.markers_per_array} markers per array, but the tracks have "
                         f"{markers_per_array}; is it the sequence of these tracks?")
    return markers


# -- parsing -----------------------------------------------------------------------------


def parse_scale(text: str) -> ScaleMeasurement:
    """Parse a ``--scale`` value (see the module docstring); ValueError naming the bad part."""
    where = f"scale measurement {text!r}"
    kind, colon, rest = str(text).strip().partition(":")
    if not colon:
        raise ValueError(f"{where}: expected {SYNTAX}")
    if kind not in KINDS:
        raise ValueError(f"{where}: unknown kind {kind!r} (expected {', '.join(KINDS)})")
    subject, equals, value = rest.rpartition("=")
    if not equals and kind != "marker-size":
        raise ValueError(f"{where}: expected {FORMS[kind]}")
    if not equals:
        subject, value = "", rest
    metres = _parse_metres(where, value)
    if kind == "camera-height":
        return ScaleMeasurement(kind, metres, (_parse_camera(where, subject),), text=text)
    if kind == "distance":
        return ScaleMeasurement(kind, metres, _parse_camera_pair(where, subject), text=text)
    return ScaleMeasurement(kind, metres, marker=_parse_marker(where, subject, equals), text=text)


def _parse_metres(where: str, value: str) -> float:
    try:
        metres = float(value)
    except ValueError:
        raise ValueError(f"{where}: {value.strip()!r} is not a length in metres") from None
    if not (math.isfinite(metres) and metres > 0):
        raise ValueError(f"{where}: the length must be a positive number of metres, got {value.strip()!r}")
    return metres


def _parse_camera(where: str, subject: str) -> str:
    name = subject.strip()
    if not name:
        raise ValueError(f"{where}: no camera name (expected camera-height:NAME=METRES)")
    return name


def _parse_camera_pair(where: str, subject: str) -> tuple[str, str]:
    names = [name.strip() for name in subject.split(",")]
    if len(names) != 2 or not all(names):
        raise ValueError(f"{where}: expected two cameras CAM_A,CAM_B before '=', got {subject!r}")
    if names[0] == names[1]:
        raise ValueError(f"{where}: a distance needs two different cameras, got {names[0]!r} twice")
    return names[0], names[1]


def _parse_marker(where: str, subject: str, has_subject: str) -> tuple[int, int] | None:
    if not has_subject:
        return None
    match = re.fullmatch(r"\s*(\d+)\s*/\s*(\d+)\s*", subject)
    if not match:
        raise ValueError(f"{where}: the marker must be ARRAY/MARKER (two indices from 0), got {subject!r}")
    return int(match.group(1)), int(match.group(2))


# -- scale factor ------------------------------------------------------------------------


def check_measurement(
    measurement: ScaleMeasurement, camera_names: list[str] | tuple[str, ...],
    markers: ProjectedMarkers | None = None,
) -> None:
    """What can be checked before calibrating: the cameras exist, the marker is in the sequence."""
    check_cameras(measurement, camera_names)
    if measurement.kind == "marker-size":
        markers = _require_markers(measurement, markers)
        _marker_pixel(measurement, markers)


def check_cameras(measurement: ScaleMeasurement, camera_names: list[str] | tuple[str, ...]) -> None:
    """ValueError naming the first camera of the measurement not in ``camera_names`` (and
    the closest name there, when one is close: a mistyped name)."""
    for name in measurement.cameras:
        if name not in camera_names:
            close = difflib.get_close_matches(name, list(camera_names), n=1)
            hint = f"; did you mean {close[0]}?" if close else ""
            raise ValueError(f"scale measurement {str(measurement)!r}: no camera {name!r} "
                             f"(cameras: {', '.join(camera_names)}{hint})")


def scale_factor(
    calibration: Calibration,
    measurement: ScaleMeasurement | str,
    markers: ProjectedMarkers | None = None,
    radius_sides: float = DEFAULT_MARKER_RADIUS_SIDES,
) -> float:
    """Metres per calibration unit implied by the measurement.

    Args:
        calibration: the calibration to scale (any unit).
        measurement: a ``ScaleMeasurement`` or its ``--scale`` text.
        markers: the sequence's MSM geometry; needed by ``marker-size`` only.
        radius_sides: ``marker-size``: radius of the neighbourhood fitted around the
            measured marker, in marker sides at scale 1 (projector pixels).
    """
    if isinstance(measurement, str):
        measurement = parse_scale(measurement)
    if measurement.kind == "camera-height":
        length = _camera_height(calibration, measurement)
    elif measurement.kind == "distance":
        length = _camera_distance(calibration, measurement)
    else:
        length = marker_side_on_floor(calibration, measurement, _require_markers(measurement, markers), radius_sides)
    factor = measurement.metres / length
    logger.info("scale from %s: %.6g m per unit (%.6g units measured)", measurement, factor, length)
    return factor


def apply_scale(
    calibration: Calibration,
    measurement: ScaleMeasurement | str,
    markers: ProjectedMarkers | None = None,
    radius_sides: float = DEFAULT_MARKER_RADIUS_SIDES,
) -> Calibration:
    """A copy of the calibration in metres (see ``scale_factor`` for the arguments)."""
    return scaled(calibration, scale_factor(calibration, measurement, markers, radius_sides))


def scaled(calibration: Calibration, factor: float) -> Calibration:
    """A copy of the calibration with every length multiplied by ``factor``, in metres."""
    if not (math.isfinite(factor) and factor > 0):
        raise ValueError(f"scale factor must be positive and finite, got {factor}")
    if calibration.unit == "m":
        logger.warning("the calibration is already in metres; scaling it again by %.6g", factor)
    poses = {name: (R.copy(), factor * np.asarray(t, dtype=float)) for name, (R, t) in calibration.poses.items()}
    metrics = {name: dataclasses.replace(m, centre_sigma=None if m.centre_sigma is None else factor * m.centre_sigma)
               for name, m in calibration.metrics.items()}
    return dataclasses.replace(
        calibration, poses=poses, metrics=metrics, points=factor * np.asarray(calibration.points, dtype=float),
        point_ids=calibration.point_ids.copy(), unit="m", floor_rms=factor * calibration.floor_rms,
        planes=[{**plane, "offset": factor * plane["offset"]} for plane in calibration.planes],
    )


def _registered_centre(calibration: Calibration, measurement: ScaleMeasurement, name: str) -> np.ndarray:
    if name in calibration.poses:
        return calibration.center(name)
    reason = calibration.failed.get(name)
    state = f"failed to register ({reason})" if reason else "is not in the calibration"
    raise ValueError(f"scale measurement {str(measurement)!r}: camera {name!r} {state}")


def _camera_height(calibration: Calibration, measurement: ScaleMeasurement) -> float:
    height = float(_registered_centre(calibration, measurement, measurement.cameras[0])[2])
    if not height > 0:
        raise ValueError(f"scale measurement {str(measurement)!r}: camera {measurement.cameras[0]!r} "
                         f"is not above the floor in the calibration (height {height:.4g})")
    return height


def _camera_distance(calibration: Calibration, measurement: ScaleMeasurement) -> float:
    a, b = (_registered_centre(calibration, measurement, name) for name in measurement.cameras)
    distance = float(np.linalg.norm(a - b))
    if not distance > 0:
        raise ValueError(f"scale measurement {str(measurement)!r}: the two cameras are at the same place")
    return distance


# -- marker size -------------------------------------------------------------------------


def marker_side_on_floor(
    calibration: Calibration,
    measurement: ScaleMeasurement,
    markers: ProjectedMarkers,
    radius_sides: float = DEFAULT_MARKER_RADIUS_SIDES,
) -> float:
    """Mean side, in calibration units, of the measured marker at scale 1 on the floor.

    Fits the projector-to-floor homography on the reconstructed MSM centres around the
    marker (module docstring) and maps the marker's square through it.
    """
    import cv2

    if not radius_sides > 0:
        raise ValueError(f"marker neighbourhood radius must be positive, got {radius_sides} sides")
    where = f"scale measurement {str(measurement)!r}"
    centre = _marker_pixel(measurement, markers)
    ids = np.asarray(calibration.point_ids, dtype=np.int64)
    known = (ids >= 0) & (ids < markers.point_count)
    if not np.all(known):
        raise ValueError(f"{where}: the calibration has point ids beyond the sequence's "
                         f"{markers.point_count} MSMs; is it the sequence of these tracks?")
    pixels = markers.pixels(ids)
    radius = radius_sides * markers.marker_side_px
    near = np.linalg.norm(pixels - centre, axis=1) <= radius
    if np.count_nonzero(near) < MIN_MARKER_NEIGHBOURS:
        raise ValueError(
            f"{where}: only {np.count_nonzero(near)} reconstructed MSM centres within {radius:.0f} projector "
            f"pixels of the marker measured (at {centre[0]:.0f}, {centre[1]:.0f}); {MIN_MARKER_NEIGHBOURS} are "
            f"needed: measure a marker that the cameras saw"
        )
    floor_xy = np.asarray(calibration.points, dtype=float)[near, :2]  # floor frame: the floor is z = 0
    H, _ = cv2.findHomography(pixels[near], floor_xy, 0)
    if H is None:
        raise ValueError(f"{where}: the MSM centres around the marker do not fit a plane")
    _log_fit(H, pixels[near], floor_xy)
    square = centre + markers.marker_side_px * UNIT_SQUARE
    corners = cv2.perspectiveTransform(square.reshape(-1, 1, 2), H).reshape(-1, 2)
    return float(np.mean(np.linalg.norm(corners - np.roll(corners, -1, axis=0), axis=1)))


def _require_markers(measurement: ScaleMeasurement, markers: ProjectedMarkers | None) -> ProjectedMarkers:
    if markers is None:
        raise ValueError(f"scale measurement {str(measurement)!r}: marker-size needs the projection "
                         f"sequence (sequence.json) for the marker positions and size")
    return markers


def _marker_pixel(measurement: ScaleMeasurement, markers: ProjectedMarkers) -> np.ndarray:
    if measurement.marker is None:
        return markers.image_centre()
    array, marker = measurement.marker
    arrays, per_array = markers.centres_px.shape[:2]
    if array >= arrays or marker >= per_array:
        raise ValueError(f"scale measurement {str(measurement)!r}: no marker {array}/{marker} in the sequence "
                         f"({arrays} arrays of {per_array} markers, indices from 0)")
    return markers.centres_px[array, marker]


def _log_fit(H: np.ndarray, pixels: np.ndarray, floor_xy: np.ndarray) -> None:
    import cv2

    mapped = cv2.perspectiveTransform(pixels.reshape(-1, 1, 2), H).reshape(-1, 2)
    rms = float(np.sqrt(np.mean(np.sum((mapped - floor_xy) ** 2, axis=1))))
    logger.info("marker-size: floor homography fitted on %d MSM centres, RMS %.3g units", len(pixels), rms)
