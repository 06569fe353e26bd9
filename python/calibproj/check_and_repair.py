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
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from calibproj import _core
from calibproj.calibration import Calibration, CameraMetrics
from calibproj.io.intrinsics import Intrinsics
from calibproj.io.jsonio import write_json
from calibproj.option_tables import options_class
from calibproj.results import CHECK_FILE
from calibproj.tracks import Tracks

log = logging.getLogger(__name__)

CHECK_KIND = "check"
CHECK_MAJOR = 1
CHANGED = ("moved", "rezoomed")
TESTED = ("unchanged",) + CHANGED
# The working volume of the practical test: the floor under the calibrated points, up
# to this height (metres; in a calibration without a metric unit, this share of the
# highest camera's height).
VOLUME_HEIGHT_M = 2.0
VOLUME_HEIGHT_SHARE = 0.7
VOLUME_SAMPLES = 9  # per side of the floor, and 5 heights


def _check_options(self) -> None:
    _core.check.check_options(**asdict(self))


CheckOptions = options_class(
    "CheckOptions", _core.check.option_table(),
    "Knobs of the camera check (declared in the C++ core with their defaults).", __name__, frozen=True,
    methods={"__post_init__": _check_options})


@dataclass
class CameraVerdict:
    """One camera's check: its status, why, and the figures behind it (pixels are
    undistorted pixels; centre in the calibration's unit)."""

    status: str
    reason: str
    points: int = 0
    inliers: int = 0
    noise_px: float | None = None
    rms_before_px: float | None = None
    rms_after_px: float | None = None
    rotation_change_deg: float | None = None
    rotation_sigma_deg: float | None = None
    centre_change: float | None = None
    centre_sigma: float | None = None
    focal_change: float | None = None
    focal_sigma: float | None = None
    volume_shift_px: float | None = None
    R: np.ndarray | None = field(default=None, repr=False)  # as the camera is now
    t: np.ndarray | None = field(default=None, repr=False)
    focal_scale: float = 1.0

    def summary(self) -> dict[str, Any]:
        """The camera's entry of ``check.json``."""
        entry = {key: value for key, value in asdict(self).items() if key not in ("R", "t")}
        return {key: (round(value, 6) if isinstance(value, float) else value) for key, value in entry.items()}


@dataclass
class CheckResult:
    """Every camera's verdict, and whether the stored calibration can be trusted as the
    reference of a repair."""

    cameras: dict[str, CameraVerdict]
    trusted: bool
    message: str
    unit: str = "arbitrary"

    @property
    def tested(self) -> list[str]:
        """The cameras that could be tested (unchanged, moved or re-zoomed)."""
        return [name for name, verdict in self.cameras.items() if verdict.status in TESTED]

    @property
    def changed(self) -> list[str]:
        return [name for name, verdict in self.cameras.items() if verdict.status in CHANGED]

    def summary(self) -> dict[str, Any]:
        return {"unit": self.unit, "trusted": self.trusted, "message": self.message,
                "cameras": {name: verdict.summary() for name, verdict in self.cameras.items()}}


class UntrustedReference(ValueError):
    """The cameras that agree with the stored calibration are not a clear majority:
    nothing is repaired against it. ``result`` holds every camera's verdict."""

    def __init__(self, result: CheckResult, message: str) -> None:
        super().__init__(message)
        self.result = result


def check_cameras(calibration: Calibration, intrinsics: dict[str, Intrinsics], tracks: Tracks,
                  options: CheckOptions | None = None, stored_tracks: Tracks | None = None,
                  unusable: dict[str, str] | None = None) -> CheckResult:
    """Test every camera of ``calibration`` on ``tracks`` (new undistorted observations
    of its points, undistorted with ``intrinsics``). ``stored_tracks``, the observations
    the calibration was made from, give each camera's reference: the same fit to its
    own calibration's observations (without them, its stored pose and sigmas).
    ``unusable``: why some cameras have no intrinsics (they are then unknown)."""
    options = options or CheckOptions()
    if not calibration.registered or not len(calibration.points):
        raise ValueError("the stored calibration has no registered camera or no point: nothing to check against")
    stored = dict(zip(calibration.point_ids.tolist(), calibration.points))
    if not any(int(i) in stored for i in tracks.point_ids):
        raise ValueError("the check projection shows none of the calibrated points: make it with "
                         "`calibproj generate --check RESULTS` from the sequence RESULTS were calibrated from")
    volume = working_volume(calibration)
    verdicts = {}
    for name in calibration.registered:
        if name not in intrinsics:
            reason = (unusable or {}).get(name, "no intrinsics in the stored results")
            verdicts[name] = CameraVerdict("unknown", f"no usable intrinsics: {reason}")
            continue
        verdicts[name] = _check_camera(name, calibration, intrinsics.get(name), tracks, stored, volume, options,
                                       stored_tracks)
    for name, reason in calibration.failed.items():
        verdicts[name] = CameraVerdict("unknown", f"not in the stored calibration ({reason})")
    trusted, message = _majority(verdicts)
    for name, verdict in verdicts.items():
        if verdict.status in ("not seen", "unknown"):
            log.warning("camera %s %s: %s", name, verdict.status, verdict.reason)
        else:
            log.debug("camera %s %s: %s", name, verdict.status, verdict.reason)
    return CheckResult(verdicts, trusted, message, calibration.unit)


def working_volume(calibration: Calibration) -> np.ndarray:
    """Points of the working volume: a grid over the floor under the calibrated points,
    from the floor up to 2 m (or a share of the highest camera's height)."""
    points = calibration.points
    low, high = points[:, :2].min(axis=0), points[:, :2].max(axis=0)
    if calibration.unit == "m":
        top = VOLUME_HEIGHT_M
    else:
        top = VOLUME_HEIGHT_SHARE * max(float(calibration.center(name)[2]) for name in calibration.registered)
    xs, ys, zs = (np.linspace(low[0], high[0], VOLUME_SAMPLES), np.linspace(low[1], high[1], VOLUME_SAMPLES),
                  np.linspace(0.0, top, 5))
    grid = np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), axis=-1).reshape(-1, 3)
    return grid


def _held(tracks: Tracks | None, name: str, stored: dict[int, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The camera's observations of stored points in ``tracks``: the points (N, 3) and
    their pixels (N, 2)."""
    if tracks is None or name not in tracks.camera_names:
        return np.zeros((0, 3)), np.zeros((0, 2))
    ids, xy = tracks.observations(name)
    known = np.array([int(i) in stored for i in ids], dtype=bool)
    return np.array([stored[int(i)] for i in ids[known]]).reshape(-1, 3), xy[known].reshape(-1, 2)


def _check_camera(name: str, calibration: Calibration, intrinsics: Intrinsics | None, tracks: Tracks,
                  stored: dict[int, np.ndarray], volume: np.ndarray, options: CheckOptions,
                  stored_tracks: Tracks | None) -> CameraVerdict:
    if intrinsics is None:
        return CameraVerdict("unknown", "no intrinsics in the stored results")
    if intrinsics.resolution is None:
        return CameraVerdict("unknown", "its intrinsics give no image size: where the working volume lies in its "
                                        "view is not known")
    metrics = calibration.metrics.get(name)
    if metrics is None:
        return CameraVerdict("unknown", "no metrics of it in the stored results")
    ids, _ = tracks.observations(name) if name in tracks.camera_names else (np.zeros(0, np.int64), None)
    points, observed = _held(tracks, name, stored)
    if not len(points):
        seen = f"{len(ids)} observations, none of a calibrated point" if len(ids) else "no marker"
        return CameraVerdict("not seen", f"{seen}: it keeps its stored pose")
    R, t = calibration.poses[name]
    width, height = intrinsics.resolution
    reference_points, reference_observed = _held(stored_tracks, name, stored)
    try:
        result = _core.check.check_camera(
            intrinsics.K, R, t, np.radians(metrics.rotation_sigma_deg or 0.0), metrics.centre_sigma or 0.0,
            points, observed, volume, float(width), float(height), reference_points, reference_observed,
            **asdict(options))
    except ValueError as error:  # this camera's stored figures: the others are tested
        return CameraVerdict("unknown", f"not testable: {error}")
    figures = {key: getattr(result, key) for key in (
        "points", "inliers", "noise_px", "rms_before_px", "rms_after_px", "rotation_change_deg", "rotation_sigma_deg",
        "centre_change", "centre_sigma", "focal_change", "focal_sigma", "volume_shift_px", "focal_scale")}
    if result.status == "unknown":
        return CameraVerdict("unknown", result.reason, points=result.points, inliers=result.inliers)
    return CameraVerdict(result.status, result.reason, R=np.array(result.R), t=np.array(result.t), **figures)


def _majority(verdicts: dict[str, CameraVerdict]) -> tuple[bool, str]:
    tested = [name for name, verdict in verdicts.items() if verdict.status in TESTED]
    agree = [name for name in tested if verdicts[name].status == "unchanged"]
    if len(tested) < 2:
        return False, (f"{len(tested)} camera(s) tested: too few to tell whether the stored calibration holds "
                       f"(see why the others were not)")
    if 2 * len(agree) <= len(tested):
        return False, (f"only {len(agree)} of the {len(tested)} cameras tested agree with the stored calibration: "
                       f"the floor, the projector or most cameras changed; run a full calibration (calibproj "
                       f"calibrate), nothing was repaired")
    changed = len(tested) - len(agree)
    return True, f"{len(agree)} of {len(tested)} cameras unchanged" + (f", {changed} changed" if changed else "")


def repaired(calibration: Calibration, intrinsics: dict[str, Intrinsics], stored_tracks: Tracks, tracks: Tracks,
             result: CheckResult,
             weak_rotation_sigma_deg: float) -> tuple[Calibration, dict[str, Intrinsics], Tracks]:
    """The calibration with the changed cameras as they are now: their poses, focal
    lengths and observations (the check's) replaced, their metrics from the check."""
    if not result.trusted:
        raise ValueError(result.message)
    poses, metrics, intrinsics = dict(calibration.poses), dict(calibration.metrics), dict(intrinsics)
    for name in result.changed:
        verdict = result.cameras[name]
        poses[name] = (verdict.R, verdict.t)
        if verdict.focal_scale != 1.0:
            K = intrinsics[name].K.copy()
            K[:2, :2] *= verdict.focal_scale
            intrinsics[name] = replace(intrinsics[name], K=K)
        # Fitted to points the other cameras placed, it is known relative to them at
        # best as well as before: the stored sigma, or the fit's when larger.
        before = metrics[name]
        sigma = max(filter(None, (before.rotation_sigma_deg, verdict.rotation_sigma_deg)), default=None)
        centre = max(filter(None, (before.centre_sigma, verdict.centre_sigma)), default=None)
        metrics[name] = CameraMetrics(
            mean_px=verdict.rms_after_px, std_px=verdict.noise_px, observations=verdict.points,
            inliers=verdict.inliers, track2_observations=verdict.inliers, view_score=before.view_score,
            rotation_sigma_deg=sigma, centre_sigma=centre,
            weak=before.weak or (sigma is not None and sigma > weak_rotation_sigma_deg))
    return (replace(calibration, poses=poses, metrics=metrics), intrinsics,
            _with_observations_of(stored_tracks, tracks, result.changed))


def _with_observations_of(stored: Tracks, new: Tracks, cameras: list[str]) -> Tracks:
    """``stored`` with the observations of ``cameras`` replaced by their ones in ``new``."""
    names = list(stored.camera_names)
    rows_cameras, rows_ids, rows_xy = [], [], []
    for name in names:
        source = new if name in cameras else stored
        if name not in source.camera_names:
            continue
        ids, xy = source.observations(name)
        rows_cameras += [name] * len(ids)
        rows_ids.append(ids)
        rows_xy.append(xy)
    ids = np.concatenate(rows_ids) if rows_ids else np.zeros(0, np.int64)
    xy = np.concatenate(rows_xy) if rows_xy else np.zeros((0, 2))
    return Tracks.from_observations(names, rows_cameras, ids, xy, stored.markers_per_array)


def write_check(path: str | os.PathLike, result: CheckResult) -> None:
    write_json(Path(path), CHECK_KIND, CHECK_MAJOR, result.summary())


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
) -> CheckResult:
    """Check the calibration in the folder ``results`` with a check projection and, with
    ``out``, write the repaired results folder there.

    Args:
        results: a results folder of ``calibrate`` (its intrinsics, points and poses).
        source: the check projection's camera videos (a folder, ``<camera>.mp4``; then
            ``sequence`` is its ``sequence.json``), or its tracks (``Tracks`` or a
            ``tracks.json``), undistorted with the results' intrinsics.
        out: where the repaired results folder goes (written only when the stored
            calibration can be trusted: see the module's docstring); None: check only.
        options: ``CheckOptions`` (defaults documented there).
        force: replace an existing ``out`` (the whole folder).
        exports, report, workers, progress, command: as ``calibrate`` takes them.

    Raises:
        UntrustedReference: with ``out``, when the stored calibration cannot be trusted
            (its ``result`` has every verdict); nothing is written.
        ValueError: unreadable results, a source without any calibrated point, bad options.
    """
    from calibproj.ingest import ingest
    from calibproj.io.output_folder import OutputFolder
    from calibproj.pipeline import video_files, write_results
    from calibproj.provenance import provenance, write_provenance
    from calibproj.registration import RegistrationOptions
    from calibproj.io.intrinsics import intrinsics_of_cameras
    from calibproj.results import CALIBRATION_FILES, INTRINSICS_DIR, TRACKS_FILE, load_results

    from calibproj.export import parse_formats

    folder_in = Path(results)
    calibration = load_results(folder_in)
    # A bad intrinsics file leaves its own camera untested (said why), not the check.
    intrinsics, unusable = intrinsics_of_cameras(folder_in / INTRINSICS_DIR, calibration.registered)
    stored_tracks = Tracks.read(folder_in / TRACKS_FILE)
    formats = parse_formats(",".join(exports)) if exports else []
    from_videos = not (isinstance(source, Tracks) or Path(source).is_file())
    if from_videos and sequence is None:
        raise ValueError(f"{source}: checking from videos needs the check projection's sequence.json")
    # The output is claimed before the long ingest: a folder that cannot be written (or
    # exists, without force) is found at once.
    folder = OutputFolder(out, force=force, signature=CALIBRATION_FILES).open() if out is not None else None
    try:
        ingest_result = None
        if from_videos:
            ingest_result = ingest(source, sequence, folder_in / INTRINSICS_DIR, workers=workers, progress=progress)
            tracks = ingest_result.tracks
        else:
            tracks = source if isinstance(source, Tracks) else Tracks.read(source)
        result = check_cameras(calibration, intrinsics, tracks, options, stored_tracks, unusable)
        if ingest_result is not None:
            for name, error in ingest_result.failed.items():
                if name in result.cameras and result.cameras[name].status == "not seen":
                    result.cameras[name] = CameraVerdict("not seen", f"{error}: it keeps its stored pose")
        if folder is None:
            return result
        if not result.trusted:
            raise UntrustedReference(result, f"{result.message} ({Path(out)} not written)")
        fixed, fixed_intrinsics, fixed_tracks = repaired(calibration, intrinsics, stored_tracks, tracks, result,
                                                         RegistrationOptions().weak_rotation_sigma_deg)
        record = provenance(folder.path, command=command, source=source, sequence=sequence,
                            intrinsics=folder_in / INTRINSICS_DIR, model=calibration.model, checked=folder_in,
                            videos=video_files(ingest_result))
        with folder.writing() as staging:
            write_provenance(staging, record)
            write_check(staging / CHECK_FILE, result)
            write_results(staging, folder.path, fixed, fixed_tracks, fixed_intrinsics, formats, report,
                          ingest_result)
        folder.commit()
        log.info("repaired results written to %s", folder.path)
        return result
    finally:
        if folder is not None:
            folder.abort()  # nothing left to do after a commit
