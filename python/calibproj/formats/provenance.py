"""Where a results folder came from: ``provenance.json`` (``calibproj.provenance/1``).

It records when and how the calibration was made (the command line, or the Python call),
with which version, from which inputs (paths and SHA-256 of the files), which markers,
model and options, and where the metric scale came from, so that a report read months
later can be traced back and the run repeated. The core writes it
(``cpp/calibproj/formats/provenance.h``), as ``calibproj-native`` does; Python adds its
own version (``"python"``).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from calibproj import _core
from calibproj.formats.jsonio import FormatError, read_json

logger = logging.getLogger(__name__)

PROVENANCE_FILE = _core.formats.provenance_file
PROVENANCE_KIND = "provenance"
PROVENANCE_MAJOR = 1

ProvenanceRecord = _core.formats.ProvenanceRecord


def _input(value: Any) -> _core.formats.ProvenanceInput | None:
    """A path, identified when the record is written; an object given in memory by its kind
    (a ``ProvenanceInput`` as it is)."""
    if value is None or isinstance(value, _core.formats.ProvenanceInput):
        return value
    if isinstance(value, (str, os.PathLike)):
        return _core.formats.ProvenanceInput(path=os.fspath(value))
    return _core.formats.ProvenanceInput(given=f"{type(value).__name__} given in memory")


def provenance(
    *,
    command: Sequence[str] | None,
    source: Any,
    sequence: Any = None,
    intrinsics: Any = None,
    markers: str | None = None,
    model: str | None = None,
    options: Any = None,
    scale: Mapping[str, Any] | None = None,
    videos: Mapping[str, str | os.PathLike] | None = None,
    merged: Any = None,
    checked: Any = None,
) -> ProvenanceRecord:
    """What ``provenance.json`` records of a calibration (the core's ``ProvenanceRecord``;
    ``write_provenance`` adds the date, version, platform and the inputs' identities).

    Args:
        command: the command line (``["calibproj", "calibrate", ...]``); None for a
            call of the Python API.
        source: the videos folder, tracks file or ``Tracks`` calibrated.
        sequence, intrinsics: the sequence file and intrinsics folder (or objects).
        markers: the marker family (``aruco:4X4_50``, ...), when known.
        model: the bundle adjustment's model.
        options: the registration options (a ``RegistrationOptions``).
        scale: where the metric scale came from (``measurement`` and ``metres_per_unit``
            or ``error``), or None.
        videos: camera -> video file, each identified by size and time (or hash), or
            the URL of a live source.
        merged: the earlier results (or tracks file) whose observations were added.
        checked: the stored results a check repaired (``calibproj check --out``).
    """
    record = ProvenanceRecord()
    record.command = list(command) if command is not None else None
    record.runtime = [("python", sys.version.split()[0])]
    record.source, record.sequence, record.intrinsics = _input(source), _input(sequence), _input(intrinsics)
    record.merged, record.checked = _input(merged), _input(checked)
    record.videos = [(name, os.fspath(path)) for name, path in (videos or {}).items()]
    record.markers, record.model = markers, model
    if dataclasses.is_dataclass(options):
        record.set_options(**dataclasses.asdict(options))
    if scale is not None:
        record.scale = _core.formats.ScaleSource(scale["measurement"], scale.get("metres_per_unit"),
                                                 scale.get("error", ""))
    return record


def write_provenance(staging: str | os.PathLike, folder: str | os.PathLike, record: ProvenanceRecord) -> Path:
    """Writes ``staging/provenance.json`` for a results folder that will finally be at
    ``folder`` (inputs beside it are recorded relative to it)."""
    record.write(Path(staging), Path(folder), log=logger.warning)
    return Path(staging) / PROVENANCE_FILE


def read_provenance(folder: str | os.PathLike) -> dict[str, Any] | None:
    """The folder's provenance, or None when it has none or it cannot be read (logged)."""
    path = Path(folder) / PROVENANCE_FILE
    if not path.exists():
        return None
    try:
        return read_json(path, PROVENANCE_KIND, PROVENANCE_MAJOR)
    except (OSError, ValueError, FormatError) as error:
        logger.warning("%s: not read (%s); the report has no provenance", path, error)
        return None
