"""Where a results folder came from: ``provenance.json`` (``calibproj.provenance/1``).

It records when and how the calibration was made (the command line, or the Python call),
with which version, from which inputs (paths and SHA-256 of the files), which markers,
model and options, and where the metric scale came from, so that a report read months
later can be traced back and the run repeated.
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import logging
import os
import platform
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from calibproj.formats.file_names import path_as_recorded
from calibproj.formats.jsonio import FormatError, read_json, write_json
from calibproj.version import __version__

logger = logging.getLogger(__name__)

PROVENANCE_FILE = "provenance.json"
PROVENANCE_KIND = "provenance"
PROVENANCE_MAJOR = 1
# Files larger than this are identified by size and modification time only: hashing a
# folder of videos would cost as much as decoding them.
MAX_HASHED_BYTES = 64 * 1024 * 1024


def file_identity(path: str | os.PathLike | None, folder: Path) -> dict[str, Any] | None:
    """``{"path", "bytes", "sha256"}`` of a file (``modified`` instead of the hash for
    large files), ``{"path"}`` for a folder or anything unreadable, None for None; the
    path as the results ``folder`` records it (``path_as_recorded``)."""
    if path is None:
        return None
    path = Path(path)
    entry: dict[str, Any] = {"path": path_as_recorded(path, folder)}
    try:
        if not path.is_file():
            return entry
        size = path.stat().st_size
        entry["bytes"] = size
        if size > MAX_HASHED_BYTES:
            modified = datetime.datetime.fromtimestamp(path.stat().st_mtime, datetime.timezone.utc)
            entry["modified"] = modified.isoformat(timespec="seconds")
            return entry
        digest = hashlib.sha256()
        with path.open("rb") as stream:
            for block in iter(lambda: stream.read(1 << 20), b""):
                digest.update(block)
        entry["sha256"] = digest.hexdigest()
    except OSError as error:
        logger.warning("%s: not identified in %s (%s)", path, PROVENANCE_FILE, error)
    return entry


def _video_entry(path: str | os.PathLike, folder: Path) -> dict[str, Any]:
    """A video file by its identity; a live source (a URL) as it was given."""
    return {"source": str(path)} if "://" in str(path) else file_identity(path, folder)


def _input_entry(value: Any, folder: Path) -> dict[str, Any] | str | None:
    """A path as its identity; an object given in memory by its kind."""
    if value is None:
        return None
    if isinstance(value, (str, os.PathLike)):
        return file_identity(value, folder)
    return f"{type(value).__name__} given in memory"


def provenance(
    folder: str | os.PathLike,
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
) -> dict[str, Any]:
    """The body of ``provenance.json``.

    Args:
        folder: the results folder, where it will finally be (paths beside it are
            recorded relative to it).
        command: the command line (``["calibproj", "calibrate", ...]``); None for a
            call of the Python API.
        source: the videos folder, tracks file or ``Tracks`` calibrated.
        sequence, intrinsics: the sequence file and intrinsics folder (or objects).
        markers: the marker family (``aruco:4X4_50``, ...), when known.
        model: the bundle adjustment's model.
        options: the registration options (a dataclass).
        scale: where the metric scale came from (measurement, factor), or None.
        videos: camera -> video file, each identified by size and time (or hash), or
            the URL of a live source.
        merged: the earlier results (or tracks file) whose observations were added.
        checked: the stored results a check repaired (``calibproj check --out``).
    """
    folder = Path(folder)
    return {
        "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "calibproj": __version__,
        "command": list(command) if command is not None else None,
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "inputs": {
            "source": _input_entry(source, folder),
            "sequence": _input_entry(sequence, folder),
            "intrinsics": _input_entry(intrinsics, folder),
            "videos": {name: _video_entry(path, folder) for name, path in (videos or {}).items()},
            "merged": _input_entry(merged, folder) if merged is not None else None,
            **({"checked": _input_entry(checked, folder)} if checked is not None else {}),
        },
        "markers": markers,
        "model": model,
        "options": dataclasses.asdict(options) if dataclasses.is_dataclass(options) else None,
        "scale": dict(scale) if scale is not None else None,
    }


def write_provenance(folder: str | os.PathLike, body: Mapping[str, Any]) -> Path:
    path = Path(folder) / PROVENANCE_FILE
    write_json(path, PROVENANCE_KIND, PROVENANCE_MAJOR, dict(body))
    return path


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
