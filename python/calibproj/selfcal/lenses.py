"""Self-calibration: each camera's focal length and lens distortion from the projection.

The projected floor points seen by several cameras determine the cameras' intrinsics
as well as their poses (planar self-calibration: the floor's circular points are shared
by every camera, so each tilted view constrains its camera's focal length, and rows of
markers that are straight on the floor constrain the distortion). This stage takes a
calibration made with nominal intrinsics and refines, in one Ceres problem, the poses,
the floor points and the requested lens entries of every registered camera, from the
raw (distorted) pixels (``calibproj._core.selfcal``: analytic Jacobians). The policy
(what is freed, kept or held, and why) is the C++ core's (``selfcal/refinement.h``),
which ``calibproj-native calibrate --refine-intrinsics`` runs too; this module holds
the Python front end's conversions.

Observability comes from the covariance of the solution: a requested group of entries
(focal length, principal point, distortion) that the data do not determine, e.g. for
a camera looking nearly straight down or zoomed onto a small patch of floor, keeps its
given values and is reported; the others are solved again with it held.

Entries (``--refine-intrinsics``): ``focal`` (fx and fy together, their ratio kept),
``pp`` (cx, cy), ``k1``, ``k2``, ``k3``, ``tangential`` (p1, p2); ``none``. The model
refined is OpenCV's 5-coefficient one; a camera whose given distortion has more
coefficients in use is refused.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping
from dataclasses import asdict
from typing import Any

from calibproj import _core
from calibproj.formats.intrinsics import Intrinsics, intrinsics_from_json
from calibproj.formats.jsonio import FormatError, read_json
from calibproj.common.option_tables import options_class
from calibproj.formats.tracks import Tracks

logger = logging.getLogger(__name__)

# Which lens entries to refine, per camera (``RefineRequest.parse(["focal,k1,k2"])``).
RefineRequest = _core.selfcal.RefineRequest
# How the refined lenses err together (the registration takes it into the poses').
LensCovariance = _core.selfcal.LensCovariance


def _check_options(self) -> None:
    # The core's own check: both tools refuse the same values.
    _core.selfcal.check_options(**asdict(self))


# Every knob of the self-calibration, declared once in the C++ core with its default and
# help (``_core.selfcal.option_table``); the command lines of both tools walk it.
SelfCalibrationOptions = options_class(
    "SelfCalibrationOptions", _core.selfcal.option_table(), "Knobs of the self-calibration.", __name__,
    methods={"__post_init__": _check_options})


def nominal_intrinsics(name: str, resolution: tuple[int, int], fov_deg: float) -> Intrinsics:
    """A pinhole with the horizontal field of view ``fov_deg``, square pixels, the
    principal point at the image centre and no distortion: where a camera without any
    calibration starts."""
    return Intrinsics.nominal(name, *resolution, fov_deg)


def convert_tracks(tracks: Tracks, given: Mapping[str, Intrinsics], refined: Mapping[str, Intrinsics]) -> Tracks:
    """Tracks undistorted with ``given`` re-expressed as undistorted with ``refined`` (a
    camera whose intrinsics are the same in both is left as it is)."""
    return _core.selfcal.convert_tracks(tracks, dict(given), dict(refined))


SCHEMA_KIND = "self_calibration"
SCHEMA_MAJOR = 1
FILE_NAME = "self_calibration.json"


def write_self_calibration(path: str | os.PathLike, result: Any, given: Mapping[str, Intrinsics],
                           options: Any) -> None:
    """``self_calibration.json`` (by the C++ core, as ``calibproj-native`` writes it): per
    camera what was refined or held and why, the uncertainties, and the intrinsics given
    (tracks undistorted with them are converted by ``convert_tracks``)."""
    _core.selfcal.write_self_calibration(path, result, dict(given), asdict(options))


def read_given_intrinsics(path: str | os.PathLike) -> dict[str, Intrinsics]:
    """The intrinsics given to the self-calibration of a results folder's
    ``self_calibration.json`` (FormatError naming the file and entry)."""
    document = read_json(path, SCHEMA_KIND, SCHEMA_MAJOR)
    cameras = document.get("cameras")
    if not isinstance(cameras, dict):
        raise FormatError(f"{path}: cameras: expected an object {{name: report}}")
    out = {}
    for name, entry in cameras.items():
        if not isinstance(entry, dict):
            raise FormatError(f"{path}: cameras.{name}: expected an object")
        if entry.get("given_intrinsics") is not None:
            out[name] = intrinsics_from_json(entry["given_intrinsics"], name, f"{path}: cameras.{name}.given_intrinsics")
    return out
