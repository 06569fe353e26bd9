"""One command in the operating room: record every camera while the projector plays
the projection, and calibrate from what arrived.

``capture(site, out)`` reads the site file (``calibproj._core.capture.read_site``:
cameras and their sources, the projector, the projection), then

1. checks that ``out`` can be written, before anything is recorded;
2. opens every camera's source and ingests it live (``calibproj.ingest`` with
   ``live=``): each is synchronised and detected as its frames arrive, and recorded
   unchanged into the recordings folder;
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
calibrating (``calibproj.check_and_repair.check``).

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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from calibproj.calibration import Calibration
from calibproj.io.jsonio import FormatError, write_json
from calibproj.io.output_folder import OutputFolder
from calibproj.results import CALIBRATION_FILES

logger = logging.getLogger(__name__)

CAPTURE_FILE = "capture.json"
STATUS_INTERVAL_S = 2.0  # a line per camera this often while recording


@dataclass
class _CameraStatus:
    """What one camera's thread reports while the capture runs."""

    frames: int = 0
    first_frame_s: float | None = None  # since the capture started
    last_frame_s: float | None = None
    shown: tuple[int, float] | None = None  # frames and time at the last status line
    done: bool = False
    error: str | None = None


@dataclass
class CaptureLog:
    """What happened during a capture (written as ``capture.json``)."""

    site: str
    recordings: str
    cameras: dict[str, dict[str, Any]] = field(default_factory=dict)
    projection: dict[str, Any] = field(default_factory=dict)

    def write(self, path: Path) -> None:
        write_json(path, "capture", 1, {"site": self.site, "recordings": self.recordings, "cameras": self.cameras,
                                         "projection": self.projection})


class _Capture:
    """The capture's threads and their shared state."""

    def __init__(self, site: Any, recordings: Path) -> None:
        from calibproj import _core

        self.site = site
        self.started = time.monotonic()
        self.lock = threading.Lock()
        self.changed = threading.Condition(self.lock)
        self.status = {camera.name: _CameraStatus() for camera in site.cameras}
        self.sources = {camera.name: _core.video.SourceOptions(
            live=True, format=camera.options.format, ffmpeg_options=dict(camera.options.ffmpeg_options),
            open_timeout_s=camera.options.open_timeout_s, stall_timeout_s=camera.options.stall_timeout_s,
            record_path=str(recordings / f"{camera.name}.mkv")) for camera in site.cameras}
        self.player_stop = _core.capture.Stop()
        self.cancel = threading.Event()  # the ingest's: set, it stops without reporting failures
        self.threads: list[threading.Event] = []  # set when each thread has ended

    def now(self) -> float:
        return time.monotonic() - self.started

    def observe(self, name: str, decoded: int) -> None:
        with self.changed:
            status = self.status[name]
            if status.first_frame_s is None:
                status.first_frame_s = self.now()
            status.frames, status.last_frame_s = decoded, self.now()
            self.changed.notify_all()

    def finished(self, camera: Any) -> None:
        with self.changed:
            status = self.status[camera.name]
            status.done, status.error = True, camera.error
            self.changed.notify_all()

    def wait(self, predicate, timeout_s: float) -> bool:
        """Waits (in slices, so that Ctrl-C is seen) until predicate() under the lock."""
        deadline = time.monotonic() + timeout_s
        with self.changed:
            while not predicate():
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self.changed.wait(min(left, 0.2))
            return True

    def stop(self, names: list[str]) -> None:
        """Ends these cameras' reads: they fail, reported, and the others go on."""
        for name in names:
            self.sources[name].request_stop()

    def abort(self) -> None:
        """Stops the player and every camera, and waits for their threads, so that
        nothing runs or prints after the capture has failed or been interrupted."""
        self.cancel.set()
        self.player_stop.set()
        for source in self.sources.values():
            source.request_stop()
        for done in self.threads:
            done.wait(timeout=10.0)

    def spawn(self, name: str, target: Any) -> threading.Thread:
        """Starts a thread whose end ``abort`` waits for. Its own event, not
        ``Thread.join``: an interrupt inside ``Thread.start`` leaves a running thread
        that ``join`` takes for one not started, and a thread still in the core when the
        interpreter exits takes the process down."""
        done = threading.Event()

        def run() -> None:
            try:
                target()
            finally:
                done.set()

        thread = threading.Thread(target=run, name=name, daemon=True)
        self.threads.append(done)
        thread.start()
        return thread

    def log_status(self) -> None:
        with self.lock:
            lines = []
            for name, status in self.status.items():
                if status.done:
                    lines.append(f"camera {name}: done" if status.error is None else f"camera {name}: failed")
                elif status.first_frame_s is None:
                    lines.append(f"camera {name}: waiting for frames")
                else:
                    # The rate since the last line: the first frames arrive in a burst
                    # (those read ahead at opening).
                    frames, since = status.shown or (status.frames, status.last_frame_s)
                    span = status.last_frame_s - since
                    rate = f", {(status.frames - frames) / span:.1f} fps" if span > 0.5 else ""
                    status.shown = (status.frames, status.last_frame_s)
                    lines.append(f"camera {name}: {status.frames} frames{rate}")
        for line in lines:
            logger.info("%s", line)


@dataclass(frozen=True)
class _Projection:
    """What is projected and how the cameras' frames are read: the sequence and its
    video, and the intrinsics (a folder, or camera -> file)."""

    sequence: Path
    video: Path
    intrinsics: Path | Mapping[str, Path]


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
                         **calibrate_options)

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
    results folder there (as ``calibproj.check_and_repair.check`` does, plus
    ``recordings/``); returns the ``CheckResult``.

    ``sequence`` is the check projection's (``calibproj generate --check RESULTS``), its
    video ``projection`` (default: ``projection.mp4`` beside it); the cameras' frames are
    read with the stored results' intrinsics. Raises as ``capture`` does, and
    ``UntrustedReference`` as ``check`` does (the recordings are then kept).
    """
    from calibproj.check_and_repair import check
    from calibproj.results import INTRINSICS_DIR

    spec = _read_site(site)
    plan = _Projection(*_projected(spec, sequence, projection), Path(results) / INTRINSICS_DIR)

    def checked(ingest_result: Any, kept: Path) -> Any:
        return check(results, ingest_result, sequence=str(plan.sequence), out=out, options=options, force=force,
                     exports=exports, report=report, progress=progress, command=command,
                     recordings=kept if out is not None else None)

    beside = Path(out) if out is not None else Path(results).parent / f"{Path(results).name}-check"
    return _captured(spec, plan, Path(out) if out is not None else None, force, _recordings(recordings, beside),
                     progress, checked)


def _captured(spec: Any, projection: _Projection, out: Path | None, force: bool, recordings: Path,
              progress: bool, then: Any) -> Any:
    """Records (steps 1-5 of the module's list) into ``recordings``, then
    ``then(ingest_result, recordings)``; on any failure or interruption, stops
    everything and says where the recordings are kept. ``out``, the folder ``then``
    writes (None: nothing), is checked first."""
    _check_inputs(spec, projection)
    if out is not None:
        OutputFolder(out, force=force, signature=CALIBRATION_FILES).open().abort()  # writable, before recording
    recordings.mkdir(parents=True, exist_ok=False)
    run = _Capture(spec, recordings)
    log = CaptureLog(site=str(spec.path), recordings=str(recordings))
    try:
        ingest_result = _record(run, spec, projection, log, progress)
        log.write(recordings / CAPTURE_FILE)
        return then(ingest_result, recordings)
    except BaseException as error:
        run.abort()
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

    try:
        return _core.capture.read_site(Path(site))
    except _core.formats.InputError as error:
        raise FormatError(str(error)) from None


def _record(run: _Capture, site: Any, projection: _Projection, log: CaptureLog, progress: bool) -> Any:
    """Steps 2-5 of the module's list; the ingest result of every camera."""
    from calibproj.ingest import ingest

    result: dict[str, Any] = {}
    failure: list[BaseException] = []

    def ingest_all() -> None:
        try:
            result["ingest"] = ingest({c.name: c.source for c in site.cameras}, str(projection.sequence),
                                      projection.intrinsics, live=run.sources,
                                      exposures={c.name: c.exposure_s for c in site.cameras if c.exposure_s > 0},
                                      progress=False, observer=run.observe, finished=run.finished,
                                      cancel=run.cancel)
        except BaseException as error:  # noqa: BLE001 - handed to the main thread
            failure.append(error)
            with run.changed:
                run.changed.notify_all()

    worker = run.spawn("capture-ingest", ingest_all)
    logger.info("capture: opening %d camera(s)", len(run.status))
    ready = run.wait(lambda: failure or all(s.first_frame_s is not None or s.done for s in run.status.values()),
                     site.ready_s)
    if failure:
        raise failure[0]
    if not ready:
        late = [name for name, s in run.status.items() if s.first_frame_s is None and not s.done]
        logger.error("capture: no frames within %g s from %s: left out", site.ready_s, ", ".join(late))
        run.stop(late)
    if all(s.done for s in run.status.values()):
        raise RuntimeError("capture: no camera delivers frames; nothing to calibrate "
                           f"({'; '.join(s.error or '' for s in run.status.values())})")
    log.projection = _project(run, site, projection.video, progress)
    ended = time.monotonic()
    if not run.wait(lambda: failure or all(s.done for s in run.status.values()), site.end_s):
        late = [name for name, s in run.status.items() if not s.done]
        logger.error("capture: %s still without the end light code %g s after the projection: stopped",
                     ", ".join(late), site.end_s)
        run.stop(late)
    worker.join()
    if failure:
        raise failure[0]
    log.projection["cameras_done_after_end_s"] = time.monotonic() - ended
    logger.info("capture: every camera ingested %.1f s after the projection ended",
                log.projection["cameras_done_after_end_s"])
    ingest_result = result["ingest"]
    for name, status in run.status.items():
        camera = ingest_result.cameras[name]
        log.cameras[name] = {"source": camera.video, "recording": f"{name}.mkv", "frames": status.frames,
                             "first_frame_s": status.first_frame_s, "error": camera.error}
    return ingest_result


def _project(run: _Capture, site: Any, video: Path, progress: bool) -> dict[str, Any]:
    """Plays the projection in a thread (the main thread stays free for Ctrl-C) and
    returns the presentation log's summary."""
    from calibproj import _core

    outcome: dict[str, Any] = {}

    def play() -> None:
        try:
            outcome["log"] = _core.capture.play(str(video), site.projector, run.player_stop)
        except BaseException as error:  # noqa: BLE001 - handed to the main thread
            outcome["error"] = error

    logger.info("capture: projecting %s", video)
    started = run.now()
    player = run.spawn("capture-projector", play)
    next_status = time.monotonic() + STATUS_INTERVAL_S
    while player.is_alive():
        player.join(0.2)
        if progress and time.monotonic() >= next_status:
            run.log_status()
            next_status += STATUS_INTERVAL_S
    if "error" in outcome:
        raise outcome["error"]
    log = outcome["log"]
    logger.info("capture: projection shown in %.1f s (%d frames logged, %d dropped or late)", log.duration_s,
                len(log.shown_s), log.dropped_frames)
    return {"video": str(video), "started_s": started, "duration_s": log.duration_s,
            "frames_logged": len(log.shown_s), "dropped_frames": log.dropped_frames,
            "video_time_s": list(log.video_time_s), "shown_s": list(log.shown_s)}


def _check_inputs(site: Any, projection: _Projection) -> None:
    """FormatError naming what is to be projected but is not there."""
    from calibproj.sequence.sequence import Sequence

    if not projection.video.is_file():
        raise FormatError(f"{site.path}: projection {projection.video}: no such file (calibproj generate writes it)")
    Sequence.load(projection.sequence)  # FormatError naming the file


def _intrinsics_of(paths: Path | Mapping[str, Path]) -> dict[str, Any]:
    """The intrinsics that read; a camera whose file does not has failed in the ingest
    already, with the file's problem as its reason."""
    from calibproj.io.intrinsics import read_intrinsics

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
