"""The whole calibration as a user runs it: videos (or tracks) in, a results folder out.

``calibrate(source, intrinsics, ...)`` takes camera videos (with the projection's
``sequence.json``) or tracks, registers the cameras, optionally puts them in metres,
and, given ``out``, writes the results folder: ``camera_poses.json``,
``metrics.json``, ``points.ply``, ``tracks.json`` (and ``detect_report.json`` from
videos), ``intrinsics/`` (the files used), exports, and ``report.html`` with
``report/*.png`` (``calibproj.formats.results``).

The folder is written as one transaction (``calibproj.formats.output_folder``): checked and
locked before the ingest starts, written beside it and moved into place at the end; an
existing folder is only replaced, whole, with ``force``, and a run that fails or is
interrupted leaves the previous folder as it was.
"""

from __future__ import annotations

import logging
import os
from dataclasses import asdict
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from calibproj import _core
from calibproj.formats.calibration import Calibration
from calibproj.formats.intrinsics import Intrinsics, has_intrinsics_file, intrinsics_of_cameras, write_intrinsics_dir
from calibproj.ingest.videos import IngestResult
from calibproj.ingest.inputs import check_videos
from calibproj.ingest.options import IngestOptions
from calibproj.formats.output_folder import OutputFolder
from calibproj.registration.driver import RegistrationOptions
from calibproj.registration.driver import register
from calibproj.formats.provenance import provenance, write_provenance
from calibproj.selfcal.lenses import FILE_NAME as SELF_CALIBRATION_FILE
from calibproj.selfcal.lenses import RefineRequest, SelfCalibrationOptions, nominal_intrinsics, write_self_calibration
from calibproj.formats.results import (CALIBRATION_FILES, DETECT_REPORT_FILE, FRAMES_DIR, INTRINSICS_DIR, RECORDINGS_DIR,
                               TRACKS_FILE)
from calibproj.formats.tracks import Tracks
from calibproj.formats.jsonio import FormatError

logger = logging.getLogger(__name__)

def calibrate(
    source: Tracks | IngestResult | str | os.PathLike,
    intrinsics: Mapping[str, Intrinsics] | str | os.PathLike | None,
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
    exposures: Mapping[str, float] | None = None,
    workers: int = 2,
    progress: bool = True,
    command: list[str] | None = None,
    refine_intrinsics: str | Sequence[str] | None = None,
    self_calibration_options: SelfCalibrationOptions | None = None,
    nominal_fov_deg: float | None = None,
    merge: str | os.PathLike | None = None,
    recordings: str | os.PathLike | None = None,
    site: str | os.PathLike | None = None,
) -> Calibration:
    """Calibrate a camera network and, with ``out``, write its results folder.

    Args:
        source: ``Tracks``, a ``tracks.json``, a folder of camera videos
            (``<camera>.mp4``; then ``sequence`` is required), or the
            ``calibproj.ingest.videos.IngestResult`` of videos already ingested (a capture's).
        intrinsics: camera name -> ``Intrinsics``, or a folder of intrinsics files.
        sequence: the projection's ``sequence.json`` (or ``Sequence``): needed for
            videos and for ``scale="marker-size:..."``.
        out: results folder; nothing is written without it.
        options: registration knobs (``RegistrationOptions``; defaults of the paper).
        scale: one metric measurement (``calibproj.scale.metric``), e.g. ``"camera-height:far1=2.7"``;
            None keeps the arbitrary unit (first registered camera at height 1).
        exports: any of ``yaml``, ``colmap``, ``anipose`` (``calibproj.formats.export``).
        report: write ``report.html`` and ``report/*.png`` (needs ``out``).
        force: replace an existing results folder ``out`` (the whole folder: nothing
            of the earlier run remains); without it an existing folder is an error.
        ingest_options, detector_options, exposures, workers, progress: passed to
            ``calibproj.ingest.videos.ingest`` when ``source`` is videos (``exposures``: known
            exposure times of some cameras, name -> seconds). With
            ``refine_intrinsics`` and no ``ingest_options``, the ingest's local check
            (``consistency_local_neighbours``) is off: it compares each centre with its
            neighbours to a fraction of a pixel, which a lens still to be refined does
            not allow.
        command: the command line to record in ``provenance.json`` (None: a Python call).
        refine_intrinsics: lens entries to refine from the projection itself
            (``calibproj.selfcal.lenses``), e.g. ``"focal,k1,k2"`` for every camera or
            ``["focal,k1,k2", "ceiling=none"]``; the intrinsics given are the start. The
            refined intrinsics are the ones in ``intrinsics/``, ``tracks.json`` is
            undistorted with them, and ``self_calibration.json`` says, per camera, what was
            refined or held and why. None (default): the intrinsics given are used as they are.
        self_calibration_options: knobs of that refinement (``SelfCalibrationOptions``).
        nominal_fov_deg: with videos and ``refine_intrinsics``: a camera without an
            intrinsics file (or every camera, when ``intrinsics`` is None) starts from a
            pinhole with this horizontal field of view, the principal point at the image
            centre and no distortion (``calibproj.selfcal.lenses.nominal_intrinsics``).
        merge: the results folder (or ``tracks.json``) of an earlier calibration of the same
            cameras, whose observations are added to the new ones: the new projection is
            then one that ``calibproj generate --densify`` planned from those results (its
            point ids are new) and ``sequence`` is that densified sequence. A camera the
            new projection gives nothing keeps its earlier observations. The intrinsics
            must be the ones the earlier results used. None (default): nothing merged.
        recordings: a folder (the capture's recorded videos) moved into the results folder
            as ``recordings/`` when the results are written; left where it is otherwise.
        site: the site file of the capture that recorded ``source``
            (``calibproj.capture``): ``provenance.json`` names it as the source, and the
            site file's intrinsics files as the intrinsics. None (default): not a capture.
    """
    from calibproj.formats.export import parse_formats
    from calibproj.scale.metric import check_measurement, parse_scale, scale_factor, scaled

    formats = parse_formats(",".join(exports)) if exports else []
    request = _refine_request(refine_intrinsics) if refine_intrinsics else None
    if request is not None and ingest_options is None:
        ingest_options = IngestOptions(**dict(_core.ingest.unrefined_lens_changes()))
    measurement = parse_scale(scale) if scale else None
    if measurement is not None and measurement.kind == "marker-size" and sequence is None:
        raise ValueError(f"--scale {scale}: marker-size needs --sequence (the projection's sequence.json)")
    videos = _videos_folder(source)
    if measurement is not None and videos is not None:  # before the long ingest
        check_measurement(measurement, video_camera_names(videos),
                          _projected_markers(sequence, None) if measurement.kind == "marker-size" else None)
    if request is not None and videos is not None:
        request.check_cameras(video_camera_names(videos))
    if exposures and videos is None:
        raise ValueError("exposures apply to videos, not to tracks")
    if exposures:
        from calibproj.ingest.videos import check_exposures

        check_exposures(exposures, video_camera_names(videos))
    _check_nominal_fov(nominal_fov_deg, request, videos, intrinsics)
    folder = OutputFolder(out, force=force, signature=CALIBRATION_FILES).open() if out is not None else None
    try:
        earlier_cameras = _earlier_cameras(merge) if merge is not None else []
        if videos is not None:  # the output is known to be writable: now the inputs, before the ingest
            check_videos(videos, sequence, intrinsics if nominal_fov_deg is None else None, earlier_cameras)
        intrinsics_source = intrinsics
        given = source if videos is not None or isinstance(source, (Tracks, IngestResult)) else Tracks.read(source)
        # Before the ingest: a bad or missing file fails its own camera only (the reason
        # names the file and the problem), a missing or empty folder the whole run.
        if nominal_fov_deg is None:
            names = (video_camera_names(videos) if videos is not None
                     else list(given.cameras) if isinstance(given, IngestResult) else list(given.camera_names))
            intrinsics, unusable = intrinsics_of_cameras(
                intrinsics_source, names + [name for name in earlier_cameras if name not in names])
        else:
            intrinsics, unusable = _with_nominal(intrinsics_source, videos, nominal_fov_deg)
        tracks, ingest_failed, ingest_result = _tracks_of(given, sequence,
                                                          intrinsics if nominal_fov_deg is not None else intrinsics_source,
                                                          ingest_options, detector_options, exposures,
                                                          workers, progress)
        if merge is not None:
            tracks, ingest_failed = _with_earlier(merge, tracks, intrinsics, ingest_failed)
        left_out = _left_out(ingest_failed, unusable)
        markers = _projected_markers(sequence, tracks.markers_per_array) if sequence is not None else None
        if measurement is not None:
            check_measurement(measurement, tracks.camera_names, markers)
        calibration = register(tracks, intrinsics, options, left_out=left_out, projector=markers)
        self_calibration = None
        if request is not None:
            calibration, tracks, intrinsics, self_calibration = _self_calibrate(
                tracks, intrinsics, calibration, request, self_calibration_options, options, left_out, markers)
        scale_error, scale_source = None, None
        if measurement is not None and calibration.registered:
            try:
                factor = scale_factor(calibration, measurement, markers)
                calibration = scaled(calibration, factor)
                scale_source = {"measurement": str(measurement), "metres_per_unit": factor}
            except ValueError as error:
                if folder is None:
                    raise
                scale_error = error
                scale_source = {"measurement": str(measurement), "error": str(error)}
        if folder is not None:
            markers_spec = ingest_result.markers if ingest_result is not None else None
            recorded = (source, intrinsics_source) if site is None else (
                site, _core.capture.site_intrinsics_provenance())
            record = provenance(command=command, source=recorded[0], sequence=sequence,
                                intrinsics=recorded[1], markers=markers_spec, model=calibration.model,
                                options=options, scale=scale_source, videos=video_files(ingest_result),
                                merged=merge)
            with folder.writing() as staging:
                write_provenance(staging, folder.path, record)  # first, as the self-calibration: the report shows them
                if self_calibration is not None:
                    write_self_calibration(staging / SELF_CALIBRATION_FILE, *self_calibration)
                write_results(staging, folder.path, calibration, tracks, intrinsics, formats, report,
                               ingest_result)
            commit_results(folder, recordings)
            logger.info("results written to %s", folder.path)
        if scale_error is not None:
            raise ValueError(f"{scale_error}; results written to {out} in arbitrary units")
    finally:
        if folder is not None:
            folder.abort()  # nothing to do after the commit
    return calibration


def _refine_request(items: str | Sequence[str]) -> RefineRequest:
    """The request of ``"focal,k1"`` or of several ``"[CAMERA=]entries"`` items."""
    return RefineRequest.parse([items] if isinstance(items, str) else list(items))


def _check_nominal_fov(fov_deg: float | None, request: RefineRequest | None, videos: Path | None,
                       intrinsics: Any) -> None:
    """ValueError unless a nominal field of view, if given, can be used."""
    if fov_deg is None:
        if intrinsics is None:
            raise ValueError("no intrinsics: give --intrinsics DIR, or --nominal-fov DEG with --refine-intrinsics")
        return
    if request is None:
        raise ValueError("--nominal-fov needs --refine-intrinsics: a guessed focal length must be refined")
    if videos is None:
        raise ValueError("--nominal-fov needs videos (their frame size); calibrating from tracks needs --intrinsics")
    if not (isinstance(fov_deg, (int, float)) and 10.0 <= fov_deg <= 170.0):
        raise ValueError(f"--nominal-fov must be a horizontal field of view in [10, 170] degrees, got {fov_deg!r}")


def _with_nominal(source: Any, videos: Path, fov_deg: float) -> tuple[dict[str, Intrinsics], dict[str, str]]:
    """The intrinsics of the cameras of ``videos``: from their file where there is one
    (a bad file still fails its camera), else nominal ones from the video's frame size."""
    names = video_camera_names(videos)
    with_file = [name for name in names if source is not None and has_intrinsics_file(source, name)]
    found, unusable = intrinsics_of_cameras(source, with_file) if with_file else ({}, {})
    for name in names:
        if name in with_file:
            continue
        try:
            info = _core.video.probe(str(next(p for p in videos.iterdir() if p.stem == name)))
        except RuntimeError as error:
            unusable[name] = str(error)
            continue
        found[name] = nominal_intrinsics(name, (info.width, info.height), fov_deg)
        logger.info("camera %s: no intrinsics file; starting from a %g deg field of view", name, fov_deg)
    return found, unusable


def _self_calibrate(tracks: Tracks, given: Mapping[str, Intrinsics], calibration: Calibration,
                    request: RefineRequest, options: SelfCalibrationOptions | None,
                    registration: RegistrationOptions | None, left_out: Mapping[str, str], projector: Any = None):
    """The calibration registered again with intrinsics refined from the first one, by
    the core's rounds (``selfcal/rounds.h``, which calibproj-native runs too), each
    registration made by this package's driver:
    ``(calibration, tracks, intrinsics, (self-calibration, given intrinsics, options))``."""
    options = options or SelfCalibrationOptions()
    if not calibration.registered:
        return calibration, tracks, given, None

    def register_tracks(tracks: Tracks, intrinsics: dict[str, Intrinsics], lens_covariance: Any) -> Calibration:
        return register(tracks, intrinsics, registration, left_out=left_out, projector=projector,
                        lens_covariance=lens_covariance)

    refined = _core.selfcal.refine_with_registrations(
        calibration, tracks, dict(given), request, options=asdict(options),
        num_threads=registration.num_threads if registration is not None else 1, register=register_tracks,
        log=logger.info)
    for name, reason in refined.weak:
        logger.warning("camera %s is weak: %s", name, reason)
    return refined.calibration, refined.tracks, dict(refined.intrinsics), (refined.result, given, options)


def _videos_folder(source: Tracks | str | os.PathLike) -> Path | None:
    """The videos folder ``source`` names, or None when it names tracks."""
    if isinstance(source, (Tracks, IngestResult)):
        return None
    path = Path(source)
    return None if path.is_file() or path.suffix.lower() == ".json" else path


def video_camera_names(folder: Path) -> list[str]:
    """The cameras of a videos folder as the ingest names them (video file stems)."""
    from calibproj.ingest.videos import VIDEO_SUFFIXES

    if not folder.is_dir():
        return []
    return sorted({p.stem for p in folder.iterdir() if p.is_file() and p.suffix.lower() in VIDEO_SUFFIXES})


def _tracks_of(source, sequence, intrinsics, ingest_options, detector_options, exposures, workers, progress):
    """(tracks, cameras that failed before registration, the ingest result or None)."""
    if isinstance(source, IngestResult):
        return source.tracks, source.failed, source
    path = _videos_folder(source)
    if path is None:
        return (source, {}, None) if isinstance(source, Tracks) else (Tracks.read(source), {}, None)
    if not path.is_dir():
        raise FileNotFoundError(f"{path}: no such videos folder")
    if sequence is None:
        raise ValueError(f"{path}: calibrating from videos needs the projection's sequence.json")
    from calibproj.ingest.videos import ingest

    result = ingest(path, sequence, intrinsics, options=ingest_options, detector_options=detector_options,
                    workers=workers, progress=progress, exposures=exposures)
    return result.tracks, result.failed, result  # the ingest logged each failure as it happened


def _earlier_cameras(merge: str | os.PathLike) -> list[str]:
    """The cameras of the earlier observations to merge (FormatError naming the file)."""
    path = Path(merge)
    return list(Tracks.read(path / TRACKS_FILE if path.is_dir() else path).camera_names)


def _with_earlier(merge: str | os.PathLike, tracks: Tracks, intrinsics: Mapping[str, Intrinsics],
                  ingest_failed: dict[str, str]) -> tuple[Tracks, dict[str, str]]:
    """The new tracks with the earlier observations added, and the cameras that still
    failed: one the new projection gave nothing keeps its earlier observations."""
    from calibproj import _core

    merged = _core.formats.with_earlier_observations(Path(merge), tracks, dict(intrinsics))
    counts = merged.counts_per_camera()
    still_failed = {}
    for name, reason in ingest_failed.items():
        if counts.get(name, 0) > 0:
            logger.warning("camera %s: nothing from the new projection (%s); its earlier observations are used",
                           name, reason)
        else:
            still_failed[name] = reason
    logger.info("merged the observations of %s: %d observations of %d points", merge, len(merged),
                merged.num_points)
    return merged, still_failed


def commit_results(folder: OutputFolder, recordings: str | os.PathLike | None) -> None:
    """Move the results folder into place, then the recordings (a capture's videos) into
    it as ``recordings/``: after the commit, so that an interruption before it leaves them
    where they were."""
    folder.commit()
    if recordings is not None:
        os.replace(recordings, folder.path / RECORDINGS_DIR)


def video_files(ingest_result: Any) -> dict[str, str]:
    return {} if ingest_result is None else {n: c.video for n, c in ingest_result.cameras.items()}


def _left_out(ingest_failed: dict[str, str], unusable_intrinsics: dict[str, str]) -> dict[str, str]:
    """The cameras that cannot enter the registration, with the reason: those the ingest
    failed (logged by the ingest) and those without usable intrinsics."""
    for name, reason in unusable_intrinsics.items():
        if name not in ingest_failed:
            logger.error("camera %s failed: %s", name, reason)
    return {**unusable_intrinsics, **ingest_failed}


def _projected_markers(sequence: Any, markers_per_array: int | None) -> Any:
    from calibproj.sequence.projected import projected_markers, read_projected_markers

    if isinstance(sequence, (str, os.PathLike)):
        return read_projected_markers(sequence, markers_per_array)
    return projected_markers(sequence)


def write_results(out: Path, final: Path, calibration: Calibration, tracks: Tracks,
                  intrinsics: Mapping[str, Intrinsics], formats: list[str], report: bool, ingest_result: Any) -> None:
    """Everything of a results folder but provenance.json, into the staging folder ``out``
    that becomes ``final``: intrinsics/, tracks.json, the detect report and frames (with
    ``ingest_result``), the calibration files, the exports and the report."""
    from calibproj.formats.export import export_all
    from calibproj.report import write_report

    used = {name: intrinsics[name] for name in tracks.camera_names if name in intrinsics}
    write_intrinsics_dir(out / INTRINSICS_DIR, used)
    tracks.write(out / TRACKS_FILE)
    if ingest_result is not None:
        thumbnails = ingest_result.write_thumbnails(out / FRAMES_DIR)
        relative = {name: Path(path).relative_to(out).as_posix() for name, path in thumbnails.items()}
        ingest_result.write_report(out / DETECT_REPORT_FILE, relative, recorded_from=final)
    calibration.save(out)
    if calibration.uncertainty is not None and calibration.poses:
        from calibproj import _core

        _core.uncertainty.write(out, calibration, used)
    if calibration.poses:
        export_all(calibration, formats, out, used, tracks)
    elif formats:  # the failures in metrics.json say why
        logger.warning("no camera registered: nothing exported")
    if report:
        write_report(out, tracks, used)
