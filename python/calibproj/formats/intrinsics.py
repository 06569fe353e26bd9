"""Camera intrinsics: the pinhole + OpenCV distortion model, and its file formats.

Three formats are read (see docs/conventions.md):

- ours, ``intrinsics/<camera>.json`` (``calibproj.intrinsics/1``);
- OpenCV YAML/XML written by ``cv2.FileStorage`` (``camera_matrix`` or ``K``,
  ``distortion_coefficients`` or ``D``, ``image_width``, ``image_height``);
- the reference code's JSON (``sensors.RGB.intrinsics.data`` and
  ``sensors.RGB.distortionCoefficients.data``), which carries no resolution.

Only ours is written. ``Intrinsics`` is the C++ core's camera type
(``cpp/calibproj/formats/camera_intrinsics.h``), and the files are read and written by
the core (``intrinsics_file.cc``), as ``calibproj-native`` reads and writes them.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from calibproj import _core
from calibproj.formats.jsonio import FormatError

Intrinsics = _core.formats.CameraIntrinsics
# The lengths of distortion vectors OpenCV takes (4, 5, 8, 12, 14).
DISTORTION_LENGTHS = _core.formats.distortion_lengths


def read_intrinsics(path: str | os.PathLike, name: str | None = None) -> Intrinsics:
    """Read one intrinsics file in any supported format (by the C++ core, as
    ``calibproj-native`` reads it); the name defaults to the file stem."""
    return _core.formats.read_intrinsics(Path(path), name or "")


def write_intrinsics(path: str | os.PathLike, intrinsics: Intrinsics, extra: Mapping[str, Any] | None = None) -> None:
    """Write our intrinsics format atomically (by the C++ core, as ``calibproj-native``
    writes it); the entries of ``extra`` (how the intrinsics were measured, their
    uncertainty) follow the format's own."""
    _core.formats.write_intrinsics(Path(path), intrinsics, dict(extra) if extra else None)


def write_intrinsics_dir(directory: str | os.PathLike, cameras: dict[str, Intrinsics]) -> None:
    """Write ``<directory>/<camera>.json`` for every camera."""
    for camera_name, intrinsics in cameras.items():
        write_intrinsics(Path(directory) / f"{camera_name}.json", intrinsics)


def load_intrinsics_dir(directory: str | os.PathLike) -> dict[str, Intrinsics]:
    """All intrinsics files of a directory, keyed by camera name (the file stem); the
    first bad file is a FormatError."""
    cameras, unusable = intrinsics_of_cameras(directory, intrinsics_files_in(directory))
    for reason in unusable.values():
        raise FormatError(reason)
    return cameras


def intrinsics_of_cameras(
    source: Mapping[str, Intrinsics] | str | os.PathLike, names: Iterable[str]
) -> tuple[dict[str, Intrinsics], dict[str, str]]:
    """The intrinsics of the named cameras, from a mapping or a directory, and why the
    others have none: ``(name -> Intrinsics, name -> reason)``. A bad, missing or
    doubled file fails its own camera only, the reason naming the file and the problem.

    Raises:
        FormatError: ``source`` is no directory, or one without any intrinsics file.
    """
    names = list(dict.fromkeys(names))
    if isinstance(source, Mapping):
        found = {name: source[name] for name in names if name in source}
        known = ", ".join(sorted(source)) or "none"
        return found, {name: f"no intrinsics for camera {name!r} (cameras with intrinsics: {known})"
                       for name in names if name not in source}
    directory = Path(source)
    intrinsics_files_in(directory)  # the folder exists and holds intrinsics files
    cameras: dict[str, Intrinsics] = {}
    unusable: dict[str, str] = {}
    for name in names:
        try:
            cameras[name] = read_intrinsics(intrinsics_file(directory, name), name)
        except FormatError as error:
            unusable[name] = str(error)
    return cameras, unusable


def has_intrinsics_file(source: Mapping[str, Intrinsics] | str | os.PathLike, name: str) -> bool:
    """Whether ``source`` (a mapping or a folder) has intrinsics, good or bad, for ``name``."""
    if isinstance(source, Mapping):
        return name in source
    try:
        return name in intrinsics_files_in(source)
    except FormatError:  # no folder, or none of its files is an intrinsics file
        return False


def intrinsics_file(directory: str | os.PathLike, name: str) -> Path:
    """The one intrinsics file of camera ``name`` in ``directory`` (the C++ core's lookup,
    which calibproj-native uses too); FormatError naming the folder or the file when
    there is none, or more than one."""
    try:
        return Path(_core.formats.intrinsics_file(Path(directory), name))
    except ValueError as error:
        raise FormatError(str(error)) from None


def intrinsics_files_in(directory: str | os.PathLike) -> dict[str, list[Path]]:
    """Camera name -> its intrinsics files in ``directory`` (one, normally)."""
    try:
        files = _core.formats.intrinsics_files(Path(directory))
    except ValueError as error:
        raise FormatError(str(error)) from None
    return {name: [Path(path) for path in paths] for name, paths in files.items()}


def intrinsics_from_json(document: Any, name: str, where: str | os.PathLike) -> Intrinsics:
    """The intrinsics of the body of our format (``Intrinsics.to_json``), checked by the
    C++ core as a file is; FormatError naming ``where`` and the problem."""
    try:
        return _core.formats.intrinsics_from_json(document, name)
    except (TypeError, ValueError) as error:
        raise FormatError(f"{where}: {error}") from None
