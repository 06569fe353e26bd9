"""The whole calibration as a user runs it: videos (or tracks) in, a results folder out.

``calibrate(source, intrinsics, ...)`` takes camera videos (with the projection's
``sequence.json``) or tracks, registers the cameras, optionally puts them in metres,
and, given ``out``, writes the results folder: ``camera_poses.json``,
``metrics.json``, ``points.ply``, ``tracks.json`` (and ``detect_report.json`` from
videos), ``intrinsics/`` (the files used), exports, and ``report.html`` with
``report/*.png``. An existing results folder is only overwritten with ``force``.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from calibproj.calibration import Calibration
from calibproj.io.intrinsics import Intrinsics, load_intrinsics_dir, write_intrinsics_dir
from calibproj.registration import RegistrationOptions
from calibproj.registration import calibrate as register
from calibproj.tracks import Tracks

logger = logging.getLogger(__name__)

RESULT_FILES = ("camera_poses.json", "metrics.json", "points.ply")


def check_output_folder(out: str | os.PathLike, force: bool) -> None:
    """ValueError if ``out`` already holds results and ``force`` is off."""
    out = Path(out)
    existing = [name for name in RESULT_FILES if (out / name).exists()]
    if existing and not force:
        raise ValueError(f"{out}: already holds results ({', '.join(existing)}); use --force to overwrite them")


def calibrate(
    source: Tracks | str | os.PathLike,
    intrinsics: Mapping[str, Intrinsics] | str | os.PathLike,
    *,
    sequence: Any = None,
    out: str | os.PathLike | None = None,
    options: RegistrationOptions | None = None,
    scale: str | None = None,
    exports: Iterable[str] = (),
    report: bool = True,
    force: bool = False,
    ingest_options: Any = None,
    detector_options: Mapping[str, Any] | None = None,
    workers: int = 2,
    progress: bool = True,
) -> Calibration:
    """Calibrate a camera network and, with ``out``, write its results folder.

    Args:
        source: ``Tracks``, a ``tracks.json``, or a folder of camera videos
            (``<camera>.mp4``; then ``sequence`` is required).
        intrinsics: camera name -> ``Intrinsics``, or a folder of intrinsics files.
        sequence: the projection's ``sequence.json`` (or ``Sequence``): needed for
            videos and for ``scale="marker-size:..."``.
        out: results folder; nothing is written without it.
        options: registration knobs (``RegistrationOptions``; defaults of the paper).
        scale: one metric measurement (``calibproj.scale``), e.g. ``"camera-height:far1=2.7"``;
            None keeps the arbitrary unit (first registered camera at height 1).
        exports: any of ``yaml``, ``colmap``, ``anipose`` (``calibproj.export``).
        report: write ``report.html`` and ``report/*.png`` (needs ``out``).
        force: overwrite the results of an earlier run in ``out``.
        ingest_options, detector_options, workers, progress: passed to
            ``calibproj.ingest.ingest`` when ``source`` is videos.
    """
    from calibproj.export import parse_formats
    from calibproj.scale import apply_scale, check_measurement, parse_scale

    if out is not None:
        check_output_folder(out, force)
    formats = parse_formats(",".join(exports)) if exports else []
    measurement = parse_scale(scale) if scale else None
    if measurement is not None and measurement.kind == "marker-size" and sequence is None:
        raise ValueError(f"--scale {scale}: marker-size needs --sequence (the projection's sequence.json)")
    intrinsics = load_intrinsics_dir(intrinsics) if isinstance(intrinsics, (str, os.PathLike)) else dict(intrinsics)

    tracks, left_out, ingest_result = _tracks_of(source, sequence, intrinsics, ingest_options, detector_options,
                                                 workers, progress)
    markers = None
    if sequence is not None and measurement is not None:
        markers = _projected_markers(sequence, tracks.markers_per_array)
    if measurement is not None:
        check_measurement(measurement, tracks.camera_names, markers)
    calibration = register(tracks, intrinsics, options, left_out=left_out)
    if measurement is not None and calibration.registered:
        try:
            calibration = apply_scale(calibration, measurement, markers)
        except ValueError as error:
            if out is None:
                raise
            _write_results(Path(out), calibration, tracks, intrinsics, formats, report, ingest_result)
            raise ValueError(f"{error}; results written to {out} in arbitrary units") from None
    if out is not None:
        _write_results(Path(out), calibration, tracks, intrinsics, formats, report, ingest_result)
    return calibration


def _tracks_of(source, sequence, intrinsics, ingest_options, detector_options, workers, progress):
    """(tracks, cameras that failed before registration, the ingest result or None)."""
    if isinstance(source, Tracks):
        return source, {}, None
    path = Path(source)
    if path.is_file() or path.suffix.lower() == ".json":
        return Tracks.read(path), {}, None
    if not path.is_dir():
        raise FileNotFoundError(f"{path}: no such videos folder")
    if sequence is None:
        raise ValueError(f"{path}: calibrating from videos needs the projection's sequence.json")
    from calibproj.ingest import ingest

    result = ingest(path, sequence, intrinsics, options=ingest_options, detector_options=detector_options,
                    workers=workers, progress=progress)
    for name, error in result.failed.items():
        logger.error("camera %s failed: %s", name, error)
    return result.tracks, result.failed, result


def _projected_markers(sequence: Any, markers_per_array: int | None) -> Any:
    from calibproj.scale import ProjectedMarkers, read_projected_markers

    if isinstance(sequence, (str, os.PathLike)):
        return read_projected_markers(sequence, markers_per_array)
    return ProjectedMarkers.from_sequence(sequence)


def _write_results(out: Path, calibration: Calibration, tracks: Tracks, intrinsics: Mapping[str, Intrinsics],
                   formats: list[str], report: bool, ingest_result: Any) -> None:
    from calibproj.export import export_all
    from calibproj.report import write_report

    out.mkdir(parents=True, exist_ok=True)
    used = {name: intrinsics[name] for name in tracks.camera_names if name in intrinsics}
    write_intrinsics_dir(out / "intrinsics", used)
    tracks.write(out / "tracks.json")
    if ingest_result is not None:
        ingest_result.write_report(out / "detect_report.json")
    calibration.save(out)
    export_all(calibration, formats, out, used, tracks)
    if report:
        page = write_report(out, tracks, used)
        logger.info("report: %s", page)
