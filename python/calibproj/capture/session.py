"""One command in the operating room: record every camera while the projector plays
the projection, and calibrate from what arrived.

``capture(site, out)`` reads the site file (``calibproj._core.capture.read_site``:
cameras and their sources, the projector, the projection), then

1. checks that ``out`` can be written, before anything is recorded;
2. runs the core's capture session (``calibproj._core.capture.record``,
   ``cpp/calibproj/capture/session.h``, which ``calibproj-native capture`` runs too)
   for steps 2-5: it opens every camera's source and ingests it live (the C++ ingest of
   ``calibproj.ingest.videos``): each is synchronised and detected as its frames arrive, and
   recorded unchanged into the recordings folder;
3. waits until every camera delivers frames (a camera that does not within the site's
   ``ready_s`` is stopped and reported; the others go on);
4. plays the projection full screen on the projector's display (libmpv, with a log of
   presentation times);
5. waits for every camera's ingest to end, which it does by itself once the end light
   code is in; a camera still running ``end_s`` after the projection ended is stopped;
6. calibrates from the ingest (``calibproj.pipeline.calibrate``): the poses are ready
   seconds after the projection ends, and the results folder gets the recordings as
   ``recordings/`` and the player's log as ``capture.json``.

``capture_check(site, results, out, sequence=...)`` does the same with a check
projection and checks (and repairs) the stored calibration ``results`` instead of
calibrating (``calibproj.check.repair.check``).

Ctrl-C or SIGTERM stops the player and every source at once. Whatever happens, the
recordings stay: in the results folder when it was written, else in the recordings
folder (``<out>-recordings-<time>`` beside it unless given), which the error names.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from calibproj.formats.calibration import Calibration
from calibproj.formats.jsonio import FormatError
from calibproj.formats.output_folder import OutputFolder
from calibproj.formats.results import CALIBRATION_FILES

logger = logging.getLogger(__name__)

CAPTURE_FILE = "capture.json"
STATUS_INTERVAL_S = 2.0  # a line per camera this often while recording


@dataclass(frozen=True)
class _Projection:
    """What is projected and how the cameras' frames are read: the sequence and its
    video, and the intrinsics (camera -> file; the site's files unless ``folder``)."""

    sequence: Path
    video: Path
    intrinsics: Mapping[str, Path]
    folder: Path | None = None  # a stored calibration's intrinsics/


def capture(
    site: str | os.PathLike,
    out: str | os.PathLike,
    *,
    force: bool = False,
    recordings: str | os.PathLike | None = None,
    progress: bool = True,
    command: list[str] | None = None,
    sequence: str | os.PathLike | None = None,
    projection: str | os.PathLike | None = None,
    **calibrate_options: Any,
) -> Calibration:
    """Records the site's cameras while its projector plays the projection, then
    calibrates them; writes the results folder ``out`` (as ``calibrate`` does, plus
    ``recordings/`` with ``capture.json``).

    Args:
        site: the site file (``calibproj.site/1``; README, "Running a room").
        out: results folder; an existing one is replaced only with ``force``.
        recordings: where the cameras are recorded (``<camera>.mkv``, packets as the
            sources sent them); default ``<out>-recordings-<YYYYmmdd-HHMMSS>`` beside
            ``out``. Moved into ``out/recordings`` with the results.
        progress: a status line per camera every few seconds while recording.
        command: the command line for ``provenance.json``.
        sequence, projection: another projection than the site file's (its
            ``sequence.json``, and its video: default ``projection.mp4`` beside it).
        calibrate_options: passed to ``calibproj.pipeline.calibrate`` (``options``,
            ``scale``, ``exports``, ``report``, ``refine_intrinsics``, ...).

    Raises:
        ValueError (``FormatError``, ``OutputError``): a bad site file, a missing
            projection or sequence, an output that cannot be written: before anything
            is recorded.
        RuntimeError: the projector cannot play (its display named); the recordings
            are kept and the message says where.
    """
    from calibproj.pipeline import calibrate

    spec = _read_site(site)
    projection = _Projection(*_projected(spec, sequence, projection),
                             {camera.name: Path(camera.intrinsics) for camera in spec.cameras})

    def calibrated(ingest_result: Any, kept: Path) -> Calibration:
        return calibrate(ingest_result, _intrinsics_of(projection.intrinsics), sequence=str(projection.sequence),
                         out=out, force=force, progress=progress, command=command, recordings=kept,
                         site=site, **calibrate_options)

    out = Path(out)
    return _captured(spec, projection, out, force, _recordings(recordings, out), progress, calibrated)


def capture_check(
    site: str | os.PathLike,
    results: str | os.PathLike,
    out: str | os.PathLike | None,
    *,
    sequence: str | os.PathLike,
    projection: str | os.PathLike | None = None,
    options: Any = None,
    force: bool = False,
    recordings: str | os.PathLike | None = None,
    progress: bool = True,
    command: list[str] | None = None,
    exports: list[str] | tuple[str, ...] = (),
    report: bool = True,
) -> Any:
    """Records the site's cameras while its projector plays a check projection, then
    checks the stored calibration ``results`` and, with ``out``, writes the repaired
    results folder there (as ``calibproj.check.repair.check`` does, plus
    ``recordings/``); returns the ``CheckResult``.

    ``sequence`` is the check projection's (``calibproj generate --check RESULTS``), its
    video ``projection`` (default: ``projection.mp4`` beside it); the cameras' frames are
    read with the stored results' intrinsics. Raises as ``capture`` does, and
    ``UntrustedReference`` as ``check`` does (the recordings are then kept).
    """
    from calibproj.check.repair import check
    from calibproj.formats.results import INTRINSICS_DIR

    spec = _read_site(site)
    folder = Path(results) / INTRINSICS_DIR
    plan = _Projection(*_projected(spec, sequence, projection), {}, folder)

    def checked(ingest_result: Any, kept: Path) -> Any:
        return check(results, ingest_result, sequence=str(plan.sequence), out=out, options=options, force=force,
                     exports=exports, report=report, progress=progress, command=command,
                     recordings=kept if out is not None else None, site=site)

    beside = Path(out) if out is not None else Path(results).parent / f"{Path(results).name}-check"
    return _captured(spec, plan, Path(out) if out is not None else None, force, _recordings(recordings, beside),
                     progress, checked)


def _captured(spec: Any, projection: _Projection, out: Path | None, force: bool, recordings: Path,
              progress: bool, then: Any) -> Any:
    """Records (steps 1-5 of the module's list) into ``recordings``, then
    ``then(ingest_result, recordings)``; on any failure or interruption, says where the
    recordings are kept. ``out``, the folder ``then`` writes (None: nothing), is
    checked first."""
    _check_inputs(spec, projection)
    if out is not None:
        OutputFolder(out, force=force, signature=CALIBRATION_FILES).open().abort()  # writable, before recording
    recordings.mkdir(parents=True, exist_ok=False)
    try:
        ingest_result = _record(spec, projection, recordings, progress)
        return then(ingest_result, recordings)
    except BaseException as error:
        if recordings.exists():
            _note_recordings(error, recordings)
        raise


def _projected(spec: Any, sequence: str | os.PathLike | None,
               projection: str | os.PathLike | None) -> tuple[Path, Path]:
    """The sequence and video to project: the site file's, or those given."""
    if sequence is None:
        return Path(spec.sequence), Path(projection) if projection is not None else Path(spec.projection)
    sequence = Path(sequence)
    return sequence, Path(projection) if projection is not None else sequence.parent / "projection.mp4"


def _read_site(site: str | os.PathLike) -> Any:
    from calibproj import _core

    return _core.capture.read_site(Path(site))


def _record(site: Any, projection: _Projection, recordings: Path, progress: bool) -> Any:
    """Steps 2-5 of the module's list, run by the core (``_core.capture.record``) in a
    thread, so that the main thread sees Ctrl-C and stops it at once; the ingest result
    of every camera."""
    from calibproj import _core
    from calibproj.ingest.videos import captured_ingest, core_detector_options
    from calibproj.ingest.options import IngestOptions
    from calibproj.sequence.sequence import Sequence

    sequence = Sequence.load(projection.sequence)
    aruco, apriltag = core_detector_options(sequence.markers.system, {})
    plan = _core.capture.CapturePlan(
        site, str(projection.sequence), sequence, str(projection.video), str(projection.folder or ""),
        str(recordings), aruco, apriltag, status_interval_s=STATUS_INTERVAL_S if progress else 0.0,
        **IngestOptions().to_kwargs())
    abort = _core.capture.Stop()
    outcome: dict[str, Any] = {}
    done = threading.Event()

    def record() -> None:
        try:
            outcome["run"] = _core.capture.record(plan, abort, _log)
        except BaseException as error:  # noqa: BLE001 - handed to the main thread
            outcome["error"] = error
        finally:
            done.set()

    # Its own event, not Thread.join: an interrupt inside Thread.start leaves a running
    # thread that join takes for one not started, and a thread still in the core when
    # the interpreter exits takes the process down.
    try:
        threading.Thread(target=record, name="capture", daemon=True).start()
        while not done.wait(0.2):
            pass
    except BaseException:
        abort.set()  # the player and every source stop at once
        done.wait(timeout=30.0)
        raise
    if "error" in outcome:
        raise outcome["error"]
    run = outcome["run"]
    run.write_log(recordings / CAPTURE_FILE)
    return captured_ingest(run, sequence, str(projection.sequence))


def _log(error: bool, line: str) -> None:
    (logger.error if error else logger.info)("%s", line)


def _check_inputs(site: Any, projection: _Projection) -> None:
    """FormatError naming what is to be projected but is not there."""
    from calibproj.sequence.sequence import Sequence

    if not projection.video.is_file():
        raise FormatError(f"{site.path}: projection {projection.video}: no such file (calibproj generate writes it)")
    Sequence.load(projection.sequence)  # FormatError naming the file


def _intrinsics_of(paths: Mapping[str, Path]) -> dict[str, Any]:
    """The intrinsics that read; a camera whose file does not has failed in the ingest
    already, with the file's problem as its reason."""
    from calibproj.formats.intrinsics import read_intrinsics

    found = {}
    for name, path in paths.items():
        try:
            found[name] = read_intrinsics(path, name)
        except (FormatError, OSError):
            continue
    return found


def _recordings(given: str | os.PathLike | None, beside: Path) -> Path:
    """The recordings folder: the one given, else ``<beside>-recordings-<time>``."""
    if given is not None:
        return Path(given)
    return beside.parent / f"{beside.name}-recordings-{time.strftime('%Y%m%d-%H%M%S')}"


def _note_recordings(error: BaseException, recordings: Path) -> None:
    """Adds where the recordings are to the error's one line."""
    note = f"; the recordings are kept in {recordings}"
    if error.args and isinstance(error.args[0], str) and note not in error.args[0]:
        error.args = (error.args[0] + note, *error.args[1:])
    elif isinstance(error, KeyboardInterrupt):
        logger.error("capture interrupted%s", note)
