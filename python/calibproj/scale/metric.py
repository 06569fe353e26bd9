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

Parsing, checks and the scale factor are the C++ core's (``cpp/calibproj/formats/
scale.cc``), the same code as ``calibproj-native calibrate --scale``.
"""

from __future__ import annotations

import logging

from calibproj import _core
from calibproj.formats.calibration import Calibration
from calibproj.sequence.projected import ProjectedMarkers

logger = logging.getLogger(__name__)

FORMS = {
    "camera-height": "camera-height:NAME=METRES",
    "marker-size": "marker-size:[ARRAY/MARKER=]METRES",
    "distance": "distance:CAM_A,CAM_B=METRES",
}
KINDS = tuple(FORMS)

# Neighbourhood of the measured marker used to fit the local floor homography, in
# marker sides at scale 1: wide enough that dozens of centres average the point
# noise out, narrow enough that a floor that is only piecewise planar still fits.
DEFAULT_MARKER_RADIUS_SIDES = _core.formats.default_marker_radius_sides
# A homography has 8 degrees of freedom; twice as many centres keep the fit stable.
MIN_MARKER_NEIGHBOURS = _core.formats.min_marker_neighbours


# One length measured in the room (the core's class): kind, metres, cameras, marker and
# the text as written; ``help(ScaleMeasurement)`` documents it.
ScaleMeasurement = _core.formats.ScaleMeasurement


# -- parsing and checks ------------------------------------------------------------------


def parse_scale(text: str) -> ScaleMeasurement:
    """Parse a ``--scale`` value (see the module docstring); ValueError naming the bad part."""
    return _core.formats.parse_scale(str(text))


def check_measurement(
    measurement: ScaleMeasurement, camera_names: list[str] | tuple[str, ...],
    markers: ProjectedMarkers | None = None,
) -> None:
    """What can be checked before calibrating: the cameras exist (a mistyped name gets
    the closest one as a hint), the marker is in the sequence."""
    _core.formats.check_measurement(measurement, list(camera_names), markers)


# -- scale factor ------------------------------------------------------------------------


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
    fit = _core.formats.scale_factor(calibration, measurement, markers, float(radius_sides))
    if measurement.kind == "marker-size":
        logger.info("marker-size: floor homography fitted on %d MSM centres, RMS %.3g units",
                    fit.fitted_centres, fit.fit_rms)
    logger.info("scale from %s: %.6g m per unit (%.6g units measured)", measurement, fit.metres_per_unit, fit.length)
    return fit.metres_per_unit


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
    if calibration.unit == "m":
        logger.warning("the calibration is already in metres; scaling it again by %.6g", factor)
    return _core.formats.scaled(calibration, float(factor))
