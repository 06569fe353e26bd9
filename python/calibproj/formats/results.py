"""The results folder of a calibration: what it holds, and reading it back.

``calibproj calibrate`` (``calibproj.pipeline``) writes the folder as one transaction
(``calibproj.formats.output_folder``); the evaluation and the report read it with
``load_results`` and ``resolve_intrinsics``. File by file:

- ``camera_poses.json``, ``metrics.json``, ``points.ply``: the calibration
  (``calibproj.formats.calibration``);
- ``tracks.json`` and, from videos, ``detect_report.json`` with ``frames/<camera>.png``
  (a grey thumbnail per camera): the observations;
- ``provenance.json``: when, how and from what the folder was made
  (``calibproj.formats.provenance``);
- ``uncertainty.json``: the poses' joint covariance and the expected 3D error over the
  working volume (``calibproj.uncertainty.triangulation``);
- ``evaluation.json``: the evaluation on independent points, when one was made
  (``calibproj evaluate --save``);
- ``intrinsics/``: the intrinsics used, one file per camera;
- ``report.html`` and ``report/*.png`` (``calibproj.report``);
- exports (``calibproj.formats.export``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

from calibproj.formats.calibration import Calibration
from calibproj.formats.intrinsics import Intrinsics, load_intrinsics_dir

CALIBRATION_FILES = ("camera_poses.json", "metrics.json", "points.ply")
TRACKS_FILE = "tracks.json"
DETECT_REPORT_FILE = "detect_report.json"
INTRINSICS_DIR = "intrinsics"
FRAMES_DIR = "frames"
RECORDINGS_DIR = "recordings"  # the videos a capture recorded
EVALUATION_FILE = "evaluation.json"
CHECK_FILE = "check.json"  # of a folder `calibproj check --out` repaired
UNCERTAINTY_FILE = "uncertainty.json"  # the poses' covariance and the expected 3D error (calibproj.uncertainty.triangulation)


def load_results(results: Calibration | str | os.PathLike) -> Calibration:
    """A ``Calibration``, read from a results folder when given a path."""
    if isinstance(results, Calibration):
        return results
    folder = Path(results)
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: no such results folder")
    return Calibration.load(folder)


def resolve_intrinsics(
    results: Calibration | str | os.PathLike,
    intrinsics: Mapping[str, Intrinsics] | str | os.PathLike | None,
) -> Mapping[str, Intrinsics]:
    """Intrinsics given, read from a folder, or from ``<results>/intrinsics``."""
    source = intrinsics_source(results, intrinsics)
    return source if isinstance(source, Mapping) else load_intrinsics_dir(source)


def intrinsics_source(
    results: Calibration | str | os.PathLike,
    intrinsics: Mapping[str, Intrinsics] | str | os.PathLike | None,
) -> Mapping[str, Intrinsics] | Path:
    """The intrinsics given, or the folder to read them from (``<results>/intrinsics``
    by default), for readers that take each camera's file on its own
    (``calibproj.formats.intrinsics.intrinsics_of_cameras``)."""
    if isinstance(intrinsics, Mapping):
        return intrinsics
    if intrinsics is not None:
        return Path(intrinsics)
    if isinstance(results, Calibration):
        raise ValueError("intrinsics are needed when the calibration is not read from a results folder")
    folder = Path(results) / INTRINSICS_DIR
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: no intrinsics in the results folder; give them with --intrinsics DIR")
    return folder
