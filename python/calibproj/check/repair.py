"""Check a stored calibration with a short projection, and repair the cameras that changed.

A check projection (``calibproj generate --check RESULTS``) shows some of the arrays the
calibration was made from again, so its points keep their ids and the stored
calibration knows where they are. Each camera's new observations of those points test
its stored pose and intrinsics (``_core.check.check_camera``: the pose, the focal length
and both fitted with the points held; the change against the same fit to the camera's
own calibration observations, judged by a chi-square with both fits' covariance and by
how far it moves the working volume in its image). A camera is then

- ``unchanged``: no change both significant and larger than the tolerance;
- ``moved``: its pose changed (the new pose is the fit against the held points);
- ``rezoomed``: its focal length changed (a PTZ camera's zoom), perhaps its pose too;
- ``not seen``: no observation of a calibrated point (covered, off, or pointed away);
  it keeps its stored pose (logged as a warning);
- ``unknown``: too few observations to test, said with how many.

The stored points stand for the floor and the cameras that placed them. If the cameras
that agree with them are not a clear majority of those tested, the floor, the
projector or most cameras changed: the check says so and repairs nothing, since it
cannot tell which side moved. Otherwise, with ``out``, the moved and re-zoomed cameras
get their new poses (and focal lengths) and a complete results folder is written, as
``calibrate`` writes one, with ``check.json``.
"""

from __future__ import annotations

import logging
import os
from dataclasses import asdict
from pathlib import Path
from typing import Any

from calibproj import _core
from calibproj.formats.calibration import Calibration
from calibproj.ingest.videos import IngestResult
from calibproj.formats.intrinsics import Intrinsics
from calibproj.common.option_tables import options_class
from calibproj.formats.results import CHECK_FILE
from calibproj.formats.tracks import Tracks

log = logging.getLogger(__name__)

def _check_options(self) -> None:
    _core.check.check_options(**asdict(self))


CheckOptions = options_class(
    "CheckOptions", _core.check.option_table(),
    "Knobs of the camera check (declared in the C++ core with their defaults).", __name__, frozen=True,
    methods={"__post_init__": _check_options})


# The check of every camera and its figures: the core's classes (one implementation with
# calibproj-native check).
CameraVerdict = _core.check.CameraVerdict
CheckResult = _core.check.CalibrationCheck


class UntrustedReference(ValueError):
    """The cameras that agree with the stored calibration are not a clear majority:
    nothing is repaired against it. ``result`` holds every camera's verdict."""

    def __init__(self, result: CheckResult, message: str) -> None:
        super().__init__(message)
        self.result = result


def check_cameras(calibration: Calibration, intrinsics: dict[str, Intrinsics], tracks: Tracks,
                  options: CheckOptions | None = None, stored_tracks: Tracks | None = None,
                  unusable: dict[str, str] | None = None, not_seen: dict[str, str] | None = None) -> CheckResult:
    """Test every camera of ``calibration`` on ``tracks`` (new undistorted observations
    of its points, undistorted with ``intrinsics``). ``stored_tracks``, the observations
    the calibration was made from, give each camera's reference: the same fit to its
    own calibration's observations (without them, its stored pose and sigmas).
    ``unusable``: why some cameras have no intrinsics (they are then unknown);
    ``not_seen``: why some gave no observation (their ingest's failure)."""
    options = options or CheckOptions()
    result = _core.check.check_calibration(calibration, intrinsics, tracks, stored_tracks, unusable or {},
                                           not_seen or {}, **asdict(options))
    for name, verdict in result.cameras.items():
        if verdict.status in ("not seen", "unknown"):
            log.warning("camera %s %s: %s", name, verdict.status, verdict.reason)
        else:
            log.debug("camera %s %s: %s", name, verdict.status, verdict.reason)
    return result


def repaired(calibration: Calibration, intrinsics: dict[str, Intrinsics], stored_tracks: Tracks, tracks: Tracks,
             result: CheckResult,
             weak_rotation_sigma_deg: float) -> tuple[Calibration, dict[str, Intrinsics], Tracks]:
    """The calibration with the changed cameras as they are now: their poses, focal
    lengths and observations (the check's) replaced, their metrics from the check (by
    the core, as calibproj-native repairs)."""
    if not result.trusted:
        raise ValueError(result.message)
    return _core.check.repaired(calibration, intrinsics, tracks, stored_tracks, result, weak_rotation_sigma_deg)


def write_check(path: str | os.PathLike, result: CheckResult) -> None:
    _core.check.write_check(Path(path), result)


def _with_stored_uncertainty(folder: Path, calibration: Calibration) -> Calibration:
    """The calibration with the covariance its folder's uncertainty.json stores, which the
    repair carries over (a bad file only costs it, with a warning)."""
    stored, warning = _core.uncertainty.stored_pose_uncertainty(folder, calibration)
    if warning:
        log.warning("%s; the repaired results will have no uncertainty.json", warning)
    return calibration.replace(uncertainty=stored)


def check(
    results: str | os.PathLike,
    source: Tracks | str | os.PathLike,
    *,
    sequence: Any = None,
    out: str | os.PathLike | None = None,
    options: CheckOptions | None = None,
    force: bool = False,
    exports: list[str] | tuple[str, ...] = (),
    report: bool = True,
    workers: int = 2,
    progress: bool = True,
    command: list[str] | None = None,
    recordings: str | os.PathLike | None = None,
    site: str | os.PathLike | None = None,
) -> CheckResult:
    """Check the calibration in the folder ``results`` with a check projection and, with
    ``out``, write the repaired results folder there.

    Args:
        results: a results folder of ``calibrate`` (its intrinsics, points and poses).
        source: the check projection's camera videos (a folder, ``<camera>.mp4``; then
            ``sequence`` is its ``sequence.json``), or its tracks (``Tracks`` or a
            ``tracks.json``), undistorted with the results' intrinsics, or the
            ``IngestResult`` of videos already ingested with them (a capture's).
        out: where the repaired results folder goes (written only when the stored
            calibration can be trusted: see the module's docstring); None: check only.
        options: ``CheckOptions`` (defaults documented there).
        force: replace an existing ``out`` (the whole folder).
        exports, report, workers, progress, command, recordings: as ``calibrate`` takes them.
        site: the site file of the capture that recorded ``source``: ``provenance.json``
            names it as the source. None (default): not a capture.

    Raises:
        UntrustedReference: with ``out``, when the stored calibration cannot be trusted
            (its ``result`` has every verdict); nothing is written.
        ValueError: unreadable results, a source without any calibrated point, bad options.
    """
    from calibproj.ingest.videos import ingest
    from calibproj.ingest.inputs import check_videos
    from calibproj.formats.output_folder import OutputFolder
    from calibproj.pipeline import commit_results, video_files, write_results
    from calibproj.formats.provenance import provenance, write_provenance
    from calibproj.registration.driver import RegistrationOptions
    from calibproj.formats.intrinsics import intrinsics_of_cameras
    from calibproj.formats.results import CALIBRATION_FILES, INTRINSICS_DIR, TRACKS_FILE, load_results

    from calibproj.formats.export import parse_formats

    folder_in = Path(results)
    calibration = _with_stored_uncertainty(folder_in, load_results(folder_in))
    # A bad intrinsics file leaves its own camera untested (said why), not the check.
    intrinsics, unusable = intrinsics_of_cameras(folder_in / INTRINSICS_DIR, calibration.registered)
    stored_tracks = Tracks.read(folder_in / TRACKS_FILE)
    formats = parse_formats(",".join(exports)) if exports else []
    ingested = isinstance(source, IngestResult)
    from_videos = not (ingested or isinstance(source, Tracks) or Path(source).is_file())
    if from_videos and sequence is None:
        raise ValueError(f"{source}: checking from videos needs the check projection's sequence.json")
    # The output is claimed before the long ingest: a folder that cannot be written (or
    # exists, without force) is found at once.
    folder = OutputFolder(out, force=force, signature=CALIBRATION_FILES).open() if out is not None else None
    try:
        ingest_result = source if ingested else None
        if ingested:
            tracks = source.tracks
        elif from_videos:
            # A single camera may be checked; the other mistakes are found before the ingest.
            check_videos(Path(source), sequence, folder_in / INTRINSICS_DIR, earlier=None)
            ingest_result = ingest(source, sequence, folder_in / INTRINSICS_DIR, workers=workers, progress=progress)
            tracks = ingest_result.tracks
        else:
            tracks = source if isinstance(source, Tracks) else Tracks.read(source)
        result = check_cameras(calibration, intrinsics, tracks, options, stored_tracks, unusable,
                               ingest_result.failed if ingest_result is not None else None)
        if folder is None:
            return result
        if not result.trusted:
            raise UntrustedReference(result, f"{result.message} ({Path(out)} not written)")
        fixed, fixed_intrinsics, fixed_tracks = repaired(calibration, intrinsics, stored_tracks, tracks, result,
                                                         RegistrationOptions().weak_rotation_sigma_deg)
        record = provenance(command=command, source=source if site is None else site, sequence=sequence,
                            intrinsics=folder_in / INTRINSICS_DIR, model=calibration.model, checked=folder_in,
                            videos=video_files(ingest_result))
        with folder.writing() as staging:
            write_provenance(staging, folder.path, record)
            write_check(staging / CHECK_FILE, result)
            write_results(staging, folder.path, fixed, fixed_tracks, fixed_intrinsics, formats, report,
                          ingest_result)
        commit_results(folder, recordings)
        log.info("repaired results written to %s", folder.path)
        return result
    finally:
        if folder is not None:
            folder.abort()  # nothing left to do after a commit
