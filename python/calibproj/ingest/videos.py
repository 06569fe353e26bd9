"""From camera videos to MSM tracks.

For every camera (the video's file stem names it), the C++ ingest
(``calibproj._core.ingest``) decodes the video once, finds the start and end light
codes of the sequence in its per-frame brightness (the map from sequence time to
camera frames: offset, rate, exposure), picks the frames that show each projected
pattern cleanly, detects the markers (in regions of interest once the
projector-to-image homography is known), undistorts their corners, takes the
diagonal intersection as the centre and merges the scales of each MSM. Cameras run
in parallel threads (the C++ core releases the GIL).

A camera that fails (unreadable or truncated video, a recording of another sequence,
no intrinsics, another resolution) is reported with a message naming the file; the
others still give tracks. Failed cameras stay in the tracks with no observations, so
that calibration reports them as not registered.
"""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibproj import _core
from calibproj.ingest.options import IngestOptions
from calibproj.formats.file_names import path_as_recorded, safe_file_names
from calibproj.formats.intrinsics import Intrinsics, intrinsics_file, read_intrinsics
from calibproj.formats.jsonio import atomic_write_bytes, write_json
from calibproj.formats.tracks import Tracks, msm_point_ids

logger = logging.getLogger(__name__)

VIDEO_SUFFIXES = (".mp4", ".mov", ".mkv", ".avi", ".m4v", ".mts", ".webm")
REPORT_KIND = "detect_report"
REPORT_MAJOR = 1
DEFAULT_WORKERS = 2
# A camera failure whose report carries the video's brightness trace.
SYNC_FAILURE = "light code not found"
BRIGHTNESS_VALUES = 1500


@dataclass
class CameraIngest:
    """What the ingest of one camera produced (or why it failed).

    Attributes:
        name: camera name (the video's file stem).
        video: path of the video.
        intrinsics: path (or description) of the intrinsics used.
        error: the failure, or None.
        raw: what the C++ ingest returned, a ``_core.ingest.CameraIngestResult`` (sync,
            statistics, per-scale ``records`` and merged ``centres`` as numpy columns,
            the luma ``signal``); None when it failed.
    """

    name: str
    video: str
    intrinsics: str
    error: str | None = None
    raw: Any = field(default=None, repr=False)
    # Mean brightness per frame of a camera whose light codes were not found, averaged
    # over `brightness_step` frames per value: what the report draws to show why.
    brightness: np.ndarray | None = field(default=None, repr=False)
    brightness_step: int = 1

    @property
    def ok(self) -> bool:
        return self.error is None

    def summary(self) -> dict[str, Any]:
        """The camera's entry of ``detect_report.json``."""
        entry: dict[str, Any] = {"video": self.video, "intrinsics": self.intrinsics,
                                 "status": "ok" if self.ok else "failed"}
        if not self.ok:
            entry["error"] = self.error
            if self.brightness is not None:
                entry["brightness"] = {"frames_per_value": self.brightness_step,
                                       "values": [round(float(v), 5) for v in self.brightness]}
            return entry
        # Built by the C++ core, as calibproj-native builds it.
        entry.update(self.raw.report)
        return entry

    def thumbnail(self) -> np.ndarray | None:
        """The grey copy of the frame where most markers were found (``IngestOptions.thumbnail_width``), or None."""
        image = self.raw.thumbnail if self.ok and self.raw is not None else None
        return image if image is not None and image.size else None


@dataclass
class IngestResult:
    """Tracks of every camera plus the per-camera reports."""

    tracks: Tracks
    cameras: dict[str, CameraIngest]
    sequence_source: str
    markers: str
    pattern_arrays: list[int] = field(default_factory=list)  # the array each pattern shows

    @property
    def failed(self) -> dict[str, str]:
        """Camera name -> error message of the cameras that failed."""
        return {name: camera.error for name, camera in self.cameras.items() if camera.error is not None}

    def report(self, thumbnails: Mapping[str, str] | None = None,
               recorded_from: str | os.PathLike | None = None) -> dict[str, Any]:
        """The body of ``detect_report.json``; ``thumbnails`` (camera -> file, relative
        to the report) adds each camera's ``thumbnail`` entry: file, pattern, array, and
        the factor from video to thumbnail pixels. With ``recorded_from`` (the folder the
        report will be in), input paths beside it are recorded relative to it."""
        def recorded(path: str) -> str:
            return path_as_recorded(path, recorded_from) if recorded_from is not None and Path(path).exists() \
                else path

        cameras = {}
        for name, camera in self.cameras.items():
            cameras[name] = camera.summary()
            for key in ("video", "intrinsics"):
                cameras[name][key] = recorded(cameras[name][key])
            if thumbnails and name in thumbnails:
                cameras[name]["thumbnail"] = self._thumbnail_entry(camera, thumbnails[name])
        return {"sequence": recorded(self.sequence_source), "markers": self.markers, "cameras": cameras}

    def _thumbnail_entry(self, camera: CameraIngest, file: str) -> dict[str, Any]:
        pattern = int(camera.raw.thumbnail_pattern)
        array = self.pattern_arrays[pattern] if 0 <= pattern < len(self.pattern_arrays) else None
        return {"file": file, "pattern": pattern, "array": array,
                "scale": camera.thumbnail().shape[1] / float(camera.raw.video.width)}

    def write_thumbnails(self, folder: str | os.PathLike) -> dict[str, str]:
        """Each camera's thumbnail as ``<folder>/<camera>.png``; camera -> file path."""
        import cv2

        written = {}
        for name, file_name in safe_file_names(list(self.cameras)).items():
            image = self.cameras[name].thumbnail()
            if image is None:
                continue
            ok, png = cv2.imencode(".png", image)
            if ok:
                path = Path(folder) / file_name
                atomic_write_bytes(path, png.tobytes())
                written[name] = str(path)
        return written

    def write_report(self, path: str | os.PathLike, thumbnails: Mapping[str, str] | None = None,
                     recorded_from: str | os.PathLike | None = None) -> None:
        """Write ``detect_report.json`` (``calibproj.detect_report/1``) atomically
        (``thumbnails`` and ``recorded_from``: see :meth:`report`)."""
        write_json(path, REPORT_KIND, REPORT_MAJOR, self.report(thumbnails, recorded_from))


def detect(
    videos: str | os.PathLike | Mapping[str, str | os.PathLike] | Iterable[str | os.PathLike],
    sequence: Any,
    intrinsics: str | os.PathLike | Mapping[str, Intrinsics | str | os.PathLike],
    *,
    options: IngestOptions | None = None,
    detector_options: Mapping[str, Any] | None = None,
    workers: int = DEFAULT_WORKERS,
    progress: bool = True,
    exposures: Mapping[str, float] | None = None,
) -> Tracks:
    """MSM tracks of every camera's video (see :func:`ingest`, which also returns the
    per-camera reports). Failed cameras are logged and kept without observations."""
    result = ingest(videos, sequence, intrinsics, options=options, detector_options=detector_options,
                    workers=workers, progress=progress, exposures=exposures)
    for name, error in result.failed.items():
        logger.error("camera %s failed: %s", name, error)
    return result.tracks


def check_exposures(exposures: Mapping[str, float], names: list[str]) -> None:
    """ValueError naming the cameras of ``exposures`` that have no video among ``names``."""
    unknown = sorted(set(exposures) - set(names))
    if unknown:
        raise ValueError(f"exposures given for camera(s) without a video: {', '.join(unknown)}")


def ingest(
    videos: str | os.PathLike | Mapping[str, str | os.PathLike] | Iterable[str | os.PathLike],
    sequence: Any,
    intrinsics: str | os.PathLike | Mapping[str, Intrinsics | str | os.PathLike],
    *,
    options: IngestOptions | None = None,
    detector_options: Mapping[str, Any] | None = None,
    workers: int = DEFAULT_WORKERS,
    progress: bool = True,
    exposures: Mapping[str, float] | None = None,
    live: Mapping[str, Any] | None = None,
    observer: Callable[[str, int], None] | None = None,
    cancel: threading.Event | None = None,
) -> IngestResult:
    """Synchronise and detect every camera's video; tracks and reports.

    Args:
        videos: a folder of videos (``<camera>.mp4``, ...), a list of video paths or
            a mapping camera name -> path.
        sequence: a ``calibproj.sequence.Sequence`` or the path of ``sequence.json``.
        intrinsics: a folder with ``<camera>.json`` (or ``.yaml``/``.yml``/``.xml``), or a
            mapping camera name -> ``Intrinsics`` or file path.
        options: :class:`calibproj.ingest.options.IngestOptions` (defaults documented there).
        detector_options: marker detector options as ``calibproj.detect_markers`` takes
            them (``corner_refinement``, ``quad_decimate``, ...); ``inverted`` comes from
            the sequence.
        workers: cameras processed at once (sharing the cores for decoding: ``options.decode_threads``).
        progress: show a progress bar per camera (on terminals).
        exposures: known exposure times in seconds of some cameras (camera name ->
            seconds), overriding ``options.exposure_s`` (see there when it matters).
        live: cameras whose "video" is a live source (a stream URL or a device), name ->
            ``calibproj._core.video.SourceOptions``: each is ingested as its frames
            arrive, all at once whatever ``workers`` says, and recorded where its options
            say; the ingest of one ends once the end light code is in.
        observer: called from the cameras' threads as ``observer(name, frames_decoded)``
            now and then (every 25 frames, and at the first).
        cancel: set from another thread, it stops every camera (live sources at once)
            and the ingest raises KeyboardInterrupt; no camera is reported as failed.

    Raises:
        ValueError: no videos, an unreadable sequence file, bad options. Per-camera
            failures do not raise; they are in ``IngestResult.failed``.
    """
    sequence, sequence_source = _load_sequence(sequence)
    options = options or IngestOptions()
    live = dict(live or {})
    paths = video_paths(videos, urls=set(live))
    unknown = sorted(set(live) - set(paths))
    if unknown:
        raise ValueError(f"live sources given for camera(s) without a source: {', '.join(unknown)}")
    aruco, apriltag = core_detector_options(sequence.markers.system, detector_options or {})
    _core.ingest.check_options(aruco, apriltag, **options.to_kwargs())  # not once per camera
    names = list(paths)
    bars = _Progress(names, enabled=progress, observer=observer, live=live, cancel=cancel)
    exposures = dict(exposures or {})
    check_exposures(exposures, names)

    at_once = min(len(names), max(1, workers, len(live)))
    decode_threads = _core.ingest.shared_decode_threads(options.decode_threads, at_once)

    def run(name: str) -> CameraIngest:
        camera_options = options.replace(exposure_s=exposures.get(name, options.exposure_s),
                                         decode_threads=decode_threads)
        job = _CameraJob(sequence, camera_options, aruco, apriltag, bars, live.get(name))
        return job.run(name, paths[name], _intrinsics_for(intrinsics, name))

    try:
        with ThreadPoolExecutor(max_workers=max(1, workers, len(live)), thread_name_prefix="ingest") as pool:
            try:
                cameras = dict(zip(names, pool.map(run, names)))
            except BaseException:
                # Before the pool waits for its threads: they stop at their next frames.
                pool.shutdown(wait=False, cancel_futures=True)
                bars.cancel()
                raise
    finally:
        bars.close()
    return _result(cameras, sequence, sequence_source)


def captured_ingest(run: Any, sequence: Any, sequence_source: str) -> IngestResult:
    """The ingest of a capture (a ``_core.capture.CaptureRun``), as ``ingest`` gives it."""
    cameras = {}
    for camera in run.cameras:
        report = CameraIngest(camera.name, camera.source, camera.intrinsics)
        if camera.ok:
            report.raw = run.ingest_result(camera.name)
        else:
            report.error = camera.error
        cameras[camera.name] = report
    return _result(cameras, sequence, sequence_source)


def _result(cameras: dict[str, CameraIngest], sequence: Any, sequence_source: str) -> IngestResult:
    tracks = _tracks(cameras, sequence.centres.shape[1])
    return IngestResult(tracks, cameras, sequence_source, sequence.markers.spec,
                        [int(p.array) for p in sequence.patterns])


class _CameraJob:
    """Runs the C++ ingest of one camera and turns failures into reports."""

    def __init__(self, sequence: Any, options: IngestOptions, aruco: Any, apriltag: Any,
                 bars: _Progress, live: Any = None) -> None:
        self.sequence = sequence  # a core Sequence, given as it is to every camera's ingest
        self.kwargs = options.to_kwargs()
        self.aruco = aruco
        self.apriltag = apriltag
        self.bars = bars
        self.live = live

    def run(self, name: str, video: Path | str, intrinsics: tuple[Intrinsics | None, str]) -> CameraIngest:
        camera_intrinsics, source = intrinsics
        report = CameraIngest(name, str(video), source)
        try:
            if camera_intrinsics is None:
                raise ValueError(source)
            report.raw = _core.ingest.ingest_camera(
                str(video), self.sequence, camera_intrinsics, source, self.aruco, self.apriltag,
                self.bars.callback(name), live=self.live, **self.kwargs)
        except (ValueError, RuntimeError, OSError) as error:
            if self.bars.cancelled.is_set():  # the C++ core reports the interruption as its error
                raise KeyboardInterrupt(f"camera {name}: ingest interrupted") from None
            self.bars.finish(name, complete=False)
            report.error = str(error)
            logger.error("camera %s failed: %s", name, error)
            if SYNC_FAILURE in report.error and self.live is None:
                report.brightness, report.brightness_step = _brightness_trace(video, self.kwargs)
        else:
            self.bars.finish(name, complete=True)
            logger.info("camera %s: %d MSMs", name, len(report.raw.centres.array))
        return report


class _Progress:
    """Per camera a progress bar (``calibproj.common.progress``: tqdm on a terminal, periodic
    log lines elsewhere), updated from the C++ threads, and the way to stop them: once
    ``cancel`` is called, the next progress call of every camera raises, which unwinds
    its C++ ingest within a fraction of a second (it calls back every 25 frames)."""

    def __init__(self, names: list[str], enabled: bool, observer: Callable[[str, int], None] | None = None,
                 live: Mapping[str, Any] | None = None,
                 cancel: threading.Event | None = None) -> None:
        self.enabled = enabled
        self.observer = observer
        self.live = dict(live or {})  # their reads are stopped at once on cancel
        self.bars: dict[str, Any] = {}
        self.lock = threading.Lock()
        self.positions = {name: index for index, name in enumerate(names)}
        self.cancelled = cancel if cancel is not None else threading.Event()

    def cancel(self) -> None:
        self.cancelled.set()
        for source in self.live.values():
            source.request_stop()

    def callback(self, name: str) -> Any:
        def update(decoded: int, total: int) -> None:
            if self.cancelled.is_set():
                raise KeyboardInterrupt(f"camera {name}: ingest interrupted")
            if self.observer is not None:
                self.observer(name, decoded)
            if not self.enabled:
                return
            bar = self._bar(name, total)
            if total > 0 and bar.total != max(total, decoded):
                bar.total = max(total, decoded)
            bar.update(decoded - bar.n)

        return update

    def _bar(self, name: str, total: int) -> Any:
        from calibproj.common.progress import progress_bar

        with self.lock:
            if name not in self.bars:
                self.bars[name] = progress_bar(total or None, f"camera {name}", position=self.positions[name])
            return self.bars[name]

    def finish(self, name: str, complete: bool) -> None:
        """Close the camera's bar as soon as its ingest ends, so that its time and rate
        are its own (not those of the slowest camera); a ``complete`` one shows all the
        frames it decoded as done (the container's frame count is an estimate)."""
        with self.lock:
            bar = self.bars.get(name)
        if bar is None:
            return
        if complete and bar.n and bar.total != bar.n:
            bar.total = bar.n
        bar.close()

    def close(self) -> None:
        # In screen order: a bar closed out of order is drawn again on a terminal.
        with self.lock:
            bars = sorted(self.bars.items(), key=lambda item: self.positions[item[0]])
        for _, bar in bars:
            bar.close()


def _brightness_trace(video: Path, kwargs: Mapping[str, Any]) -> tuple[np.ndarray | None, int]:
    """The video's mean brightness per frame, averaged down to at most
    BRIGHTNESS_VALUES values (a second decoding pass, made only for a failed sync)."""
    try:
        signal = _core.video.luma_signal(str(video), kwargs["luma_gamma"], kwargs["mean_row_step"])
    except (ValueError, RuntimeError, OSError) as error:
        logger.info("camera video %s: no brightness trace (%s)", video, error)
        return None, 1
    step = max(1, int(np.ceil(len(signal) / BRIGHTNESS_VALUES)))
    padded = np.full(step * int(np.ceil(len(signal) / step)), np.nan)
    padded[:len(signal)] = signal
    with np.errstate(invalid="ignore"):
        return np.nanmean(padded.reshape(-1, step), axis=1), step


def luma_signal(video: str | os.PathLike, options: IngestOptions | None = None) -> np.ndarray:
    """Mean linearised luma of every frame of a video (one decoding pass), as the
    synchronisation measures it (``luma_gamma``, ``mean_row_step``)."""
    options = options or IngestOptions()
    return _core.video.luma_signal(str(video), options.luma_gamma, options.mean_row_step)


def synchronise(signal: np.ndarray, sequence: Any, camera_fps: float, options: IngestOptions | None = None,
                source: str = "signal") -> Any:
    """Frame map of a camera from its per-frame mean luma (NaN = not measured).

    Returns a ``_core.sync.SyncResult``: its ``map`` (``offset``, the camera frame at
    which the sequence's frame 0 starts; ``rate``, camera frames per projector frame;
    ``exposure``, camera frames), ``offset_uncertainty`` (camera frames: the offsets
    that explain the signal as well; about a frame when no camera frame spans a light
    change), ``sharp``, ``window_map`` (a map whose exposure windows cover every one
    that fits), and per code ``start`` / ``end`` (correlation, position). RuntimeError
    naming ``source`` when a code is not found (with the best correlation seen) or the
    two codes disagree.
    """
    from calibproj.ingest.options import sync_kwargs

    sequence, _ = _load_sequence(sequence)
    levels = _core.ingest.light_levels(sequence)
    return _core.sync.synchronise(np.asarray(signal, dtype=float), levels, sequence.start_code,
                                  sequence.end_code, float(camera_fps) / float(sequence.fps), source,
                                  **sync_kwargs(options or IngestOptions(), camera_fps))


def _load_sequence(sequence: Any) -> tuple[Any, str]:
    from calibproj.sequence.sequence import Sequence

    if isinstance(sequence, Sequence):
        return sequence, "sequence"
    return Sequence.load(sequence), str(sequence)


def video_paths(videos: Any, urls: set[str] = frozenset()) -> dict[str, Path | str]:
    """Camera name -> video path, in name order; the sources of the cameras named in
    ``urls`` (live streams) are kept as given."""
    if isinstance(videos, Mapping):
        paths = {str(name): str(path) if str(name) in urls else Path(path) for name, path in videos.items()}
    elif isinstance(videos, (str, os.PathLike)):
        folder = Path(videos)
        if not folder.is_dir():
            raise ValueError(f"{folder}: no such videos folder")
        files = [p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in VIDEO_SUFFIXES]
        paths = {}
        for path in files:
            if path.stem in paths:
                raise ValueError(f"{path}: a second video for camera {path.stem!r}")
            paths[path.stem] = path
        if not paths:
            raise ValueError(f"{folder}: no videos ({', '.join('*' + s for s in VIDEO_SUFFIXES)})")
    else:
        paths = {}
        for item in videos:
            path = Path(item)
            if path.stem in paths:
                raise ValueError(f"{path}: a second video for camera {path.stem!r}")
            paths[path.stem] = path
    if not paths:
        raise ValueError("no videos given")
    return dict(sorted(paths.items()))


def _intrinsics_for(intrinsics: Any, name: str) -> tuple[Intrinsics | None, str]:
    """The camera's intrinsics and where they come from; (None, message) when missing.

    Errors stay per camera: a broken file only fails its own camera."""
    from calibproj.formats.jsonio import FormatError

    if isinstance(intrinsics, Mapping):
        entry = intrinsics.get(name)
        if entry is None:
            return None, f"no intrinsics for camera {name!r} (cameras with intrinsics: {', '.join(sorted(intrinsics))})"
        if isinstance(entry, Intrinsics):
            return entry, f"intrinsics of {name}"
    try:
        path = Path(entry) if isinstance(intrinsics, Mapping) else intrinsics_file(intrinsics, name)
        return read_intrinsics(path, name), str(path)
    except FormatError as error:
        return None, str(error)


def core_detector_options(system: str, options: Mapping[str, Any]) -> tuple[Any, Any]:
    """The core's (aruco, apriltag) detector options from options as
    ``calibproj.detect_markers`` takes them."""
    from calibproj.sequence.markers import _build_options

    return _build_options(system, dict(options))


def _tracks(cameras: dict[str, CameraIngest], markers_per_array: int) -> Tracks:
    names, ids, xy = [], [], []
    for index, camera in enumerate(cameras.values()):
        if not camera.ok:
            continue
        centres = camera.raw.centres
        point_ids = msm_point_ids(centres.array, centres.marker, markers_per_array)
        names.append(np.full(len(point_ids), index, dtype=np.int32))
        ids.append(point_ids)
        xy.append(np.asarray(centres.xy, dtype=float).reshape(-1, 2))
    if not ids:
        return Tracks.empty(list(cameras), markers_per_array)
    return Tracks.from_observations(list(cameras), np.concatenate(names), np.concatenate(ids), np.concatenate(xy),
                                    markers_per_array)
