"""Evaluate a calibration on independent data, as in the paper (section 3.2, Evaluation).

The evaluation data are image observations of points that took no part in the
calibration (``eval_tracks.json``: the paper records a ChArUco board; the simulator
draws points in the working volume). With the calibrated poses held fixed:

1. every evaluation point seen by at least two registered cameras is triangulated from
   one camera pair: the pair whose viewing rays meet at the angle closest to 90
   degrees, the best-conditioned two-view triangulation (``initialisation="pair"``),
   or from all its views at once (``"all-views"``), by the linear (DLT) method;
2. all points are refined together by bundle adjustment with the poses fixed, which
   minimises the total reprojection error over all cameras (optionally without the
   observations of cameras the calibration reports as weak wherever two other cameras
   see the point: a weak camera's pose error then does not move the points the others
   are judged on, ``weak_cameras_place_points=False``);
3. each camera's reprojection errors (undistorted pixels) give its mean, standard
   deviation and count; the success rate at a threshold is the percentage of cameras
   whose mean error is below it, counting as failures the cameras that were not
   registered, and those without a single evaluation observation.

``evaluate --json`` prints ``{"success_rate": {"0.5": f, "2": f, "5": f}, "cameras":
{name: {"mean_px", "std_px", "n"}}}`` (percentages; ``mean_px`` and ``std_px`` are
null for a camera without an error to report).

The reprojection itself (``calibproj.registration.reprojection``) is shared with the report and the
COLMAP export, which measure a calibration on its own tracks.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from calibproj.formats.calibration import Calibration
from calibproj.formats.intrinsics import Intrinsics, intrinsics_of_cameras
from calibproj.registration.reprojection import depths, project
from calibproj.formats.jsonio import write_json
from calibproj.formats.results import EVALUATION_FILE, intrinsics_source, load_results
from calibproj.formats.tracks import Tracks

logger = logging.getLogger(__name__)

THRESHOLDS_PX = (0.5, 2.0, 5.0)
INITIALISATIONS = ("pair", "all-views")
LOSSES = ("none", "huber", "cauchy")
MIN_VIEWS = 2
# Nearest depth in front of a camera at which the core's bundle adjustment projects a
# point (ba/camera.h kMinDepth): a point nearer than that is behind it for the
# refinement, and must be left out before it, not refused by it.
MIN_DEPTH = 1e-9
EVALUATION_KIND = "evaluation"
EVALUATION_MAJOR = 1


@dataclass
class EvaluationOptions:
    """Knobs of the evaluation; the defaults follow the paper.

    Attributes:
        initialisation: first estimate of each point: ``pair`` (the camera pair whose
            rays meet closest to a right angle, as the paper's pairwise triangulation)
            or ``all-views`` (DLT from every registered view).
        loss: robust loss of the refinement (``none`` minimises the plain total
            reprojection error, as the paper).
        loss_scale_px: scale of the robust loss in pixels.
        max_iterations: iterations of the refinement.
        num_threads: threads of the refinement.
        weak_cameras_place_points: the observations of cameras the calibration reports
            as weak take part in placing the points (the paper's protocol); false leaves
            them out wherever two other cameras see a point, so that a weak camera's pose
            error does not move the points the others are judged on, and the weak camera
            is judged on points it did not place (a stricter test of it).
        held_out: cameras whose observations do not place the points wherever two
            other cameras see them, weak or not: each is judged on points placed
            without it (a zoomed camera's few precise views would otherwise pull the
            points towards its own pose). ``evaluate_held_out`` holds out each camera
            in turn.
    """

    initialisation: str = "pair"
    loss: str = "none"
    loss_scale_px: float = 1.0
    max_iterations: int = 100
    num_threads: int = 1
    weak_cameras_place_points: bool = True
    held_out: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.initialisation not in INITIALISATIONS:
            raise ValueError(f"initialisation must be one of {INITIALISATIONS}, got {self.initialisation!r}")
        if self.loss not in LOSSES:
            raise ValueError(f"loss must be one of {LOSSES}, got {self.loss!r}")
        if self.max_iterations < 0 or self.num_threads < 1:
            raise ValueError("max_iterations must be >= 0 and num_threads >= 1")
        if isinstance(self.held_out, str) or not all(isinstance(name, str) for name in self.held_out):
            raise ValueError(f"held_out must be a tuple of camera names, got {self.held_out!r}")


@dataclass(frozen=True)
class CameraEvaluation:
    """One camera's reprojection errors on the evaluation data (undistorted pixels).

    ``failure`` says why the camera has no error to report, or is ``None``.
    ``behind`` counts observations of points that ended up behind the camera; they are
    left out of the errors (a pose that puts seen points behind it is reported by a
    warning).
    """

    mean_px: float | None
    std_px: float | None
    n: int
    failure: str | None = None
    behind: int = 0


@dataclass(frozen=True, eq=False)  # numpy fields
class Evaluation:
    """Result of ``evaluate``.

    Attributes:
        cameras: per camera (the calibration's and those only in the evaluation data).
        thresholds_px: the success thresholds.
        point_ids: evaluation points triangulated and refined, ``(E,)``.
        points: their refined positions in the calibration's floor frame, ``(E, 3)``.
        errors: per camera, the reprojection error of each of its observations, pixels.
        unusable_intrinsics: registered cameras left out for want of usable intrinsics,
            with the reason (the file and its problem).
    """

    cameras: dict[str, CameraEvaluation]
    thresholds_px: tuple[float, ...] = THRESHOLDS_PX
    point_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    errors: dict[str, np.ndarray] = field(default_factory=dict)
    unusable_intrinsics: dict[str, str] = field(default_factory=dict)

    def success_rate(self, threshold_px: float) -> float:
        """Percentage of cameras whose mean error is below ``threshold_px``."""
        if not self.cameras:
            return 0.0
        passed = sum(1 for c in self.cameras.values() if c.mean_px is not None and c.mean_px < threshold_px)
        return 100.0 * passed / len(self.cameras)

    @property
    def mean_px(self) -> float | None:
        """Mean error over every evaluation observation of every camera."""
        errors = [e for e in self.errors.values() if len(e)]
        return float(np.mean(np.concatenate(errors))) if errors else None

    def to_json(self) -> dict:
        """The ``evaluate --json`` document (keys fixed by DESIGN.md)."""
        return {
            "success_rate": {_threshold_key(t): self.success_rate(t) for t in self.thresholds_px},
            "cameras": {
                name: {"mean_px": c.mean_px, "std_px": c.std_px, "n": c.n} for name, c in self.cameras.items()
            },
        }

    def save(self, results_dir: str | os.PathLike, tracks_source: str | None = None,
             options: EvaluationOptions | None = None) -> Path:
        """Write ``<results_dir>/evaluation.json`` (``calibproj.evaluation/1``): the
        ``evaluate --json`` document with each failed camera's reason, the evaluation
        data's path and the options, for the report to show."""
        body = {**self.to_json(),
                "failures": {name: c.failure for name, c in self.cameras.items() if c.failure is not None},
                "tracks": tracks_source,
                "options": asdict(options or EvaluationOptions())}
        path = Path(results_dir) / EVALUATION_FILE
        write_json(path, EVALUATION_KIND, EVALUATION_MAJOR, body)
        return path


def evaluate(
    results: Calibration | str | os.PathLike,
    tracks: Tracks | str | os.PathLike,
    intrinsics: Mapping[str, Intrinsics] | str | os.PathLike | None = None,
    options: EvaluationOptions | None = None,
    thresholds_px: tuple[float, ...] = THRESHOLDS_PX,
) -> Evaluation:
    """Evaluate a calibration on independent observations (module docstring).

    Args:
        results: a ``Calibration`` or a results folder (``camera_poses.json``, ...).
        tracks: evaluation observations, ``Tracks`` or an ``eval_tracks.json``.
        intrinsics: per-camera intrinsics or their folder; ``None`` reads
            ``<results>/intrinsics`` (what ``calibrate`` writes there; when it refined
            them, ``tracks``, undistorted with the intrinsics given to it, are
            re-expressed with the refined ones).
        options: ``EvaluationOptions`` (defaults if ``None``).
        thresholds_px: success thresholds.
    """
    options = options or EvaluationOptions()
    from_results_folder = intrinsics is None and not isinstance(results, Calibration)
    calibration = load_results(results)
    source = intrinsics_source(results, intrinsics)
    tracks = tracks if isinstance(tracks, Tracks) else Tracks.read(tracks)
    unknown = sorted(set(options.held_out) - set(calibration.poses))
    if unknown:
        raise ValueError(f"held_out names no registered camera: {', '.join(unknown)} "
                         f"(registered: {', '.join(calibration.poses) or 'none'})")
    wanted = [name for name in calibration.poses if name in tracks.camera_names]
    # A bad or missing intrinsics file fails its own camera, the reason naming the file.
    intrinsics, unusable = intrinsics_of_cameras(source, wanted)
    for name, reason in unusable.items():
        logger.error("camera %s: no usable intrinsics: %s", name, reason)
    usable = [name for name in wanted if name in intrinsics]
    if from_results_folder:
        tracks = _undistorted_as_refined(Path(results), tracks, intrinsics)
    point_ids, points, errors, behind = _triangulate_and_refine(calibration, tracks, intrinsics, usable, options)
    evaluation = Evaluation(_camera_results(calibration, tracks, errors, behind, unusable), tuple(thresholds_px),
                            point_ids, points, errors, unusable)
    logger.info("evaluation: %d points refined; success %s", len(point_ids),
                ", ".join(f"{evaluation.success_rate(t):.0f} % under {_threshold_key(t)} px" for t in thresholds_px))
    return evaluation


def evaluate_held_out(
    results: Calibration | str | os.PathLike,
    tracks: Tracks | str | os.PathLike,
    intrinsics: Mapping[str, Intrinsics] | str | os.PathLike | None = None,
    options: EvaluationOptions | None = None,
) -> dict[str, CameraEvaluation]:
    """Each registered camera judged on evaluation points placed without it (the others'
    observations, wherever two of them see a point): one ``evaluate`` per camera with it
    held out; camera name -> its ``CameraEvaluation`` from its own run."""
    options = options or EvaluationOptions()
    calibration = load_results(results)
    tracks = tracks if isinstance(tracks, Tracks) else Tracks.read(tracks)  # read once for every camera
    judged = {}
    for name in calibration.poses:
        evaluation = evaluate(results, tracks, intrinsics, replace(options, held_out=(name,)))
        if name in evaluation.cameras:
            judged[name] = evaluation.cameras[name]
    return judged


def _undistorted_as_refined(results: Path, tracks: Tracks, intrinsics: Mapping[str, Intrinsics]) -> Tracks:
    """Evaluation tracks are undistorted with the intrinsics the user has; a calibration
    that refined them (``self_calibration.json``) keeps the refined ones in its folder,
    so the tracks are re-expressed with those."""
    from calibproj.selfcal.lenses import FILE_NAME, convert_tracks, read_given_intrinsics

    path = results / FILE_NAME
    if not path.is_file():
        return tracks
    given = read_given_intrinsics(path)
    logger.info("evaluation tracks re-expressed with the refined intrinsics of %s", ", ".join(sorted(given)) or "no camera")
    return convert_tracks(tracks, given, intrinsics)


# -- triangulation and refinement ----------------------------------------------------------


def _triangulate_and_refine(
    calibration: Calibration, tracks: Tracks, intrinsics: Mapping[str, Intrinsics], usable: list[str],
    options: EvaluationOptions,
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray], dict[str, int]]:
    """Points seen by >= 2 registered cameras, triangulated then refined; per-camera errors
    and per-camera counts of observations whose point lies behind the camera."""
    tracks = tracks.keep_cameras(usable).with_min_track_length(MIN_VIEWS)
    R = np.array([calibration.poses[name][0] for name in usable]).reshape(-1, 3, 3)
    t = np.array([calibration.poses[name][1] for name in usable]).reshape(-1, 3)
    K = np.array([intrinsics[name].K for name in usable]).reshape(-1, 3, 3)
    camera_index, point_index, xy = tracks.bundle_arrays()
    rays = normalised_rays(K[camera_index], xy)
    points = triangulate_tracks(R, t, camera_index, point_index, rays, tracks.num_points, options.initialisation)
    finite = np.all(np.isfinite(points), axis=1)[point_index]
    in_front = finite & (depths(R[camera_index], t[camera_index], np.nan_to_num(points[point_index])) > MIN_DEPTH)
    behind = np.bincount(camera_index[finite & ~in_front], minlength=len(usable))
    # A point left with one view in front of its cameras is not determined: drop it.
    kept = tracks.select(in_front).with_min_track_length(MIN_VIEWS)
    if kept.num_points == 0:
        logger.warning("no evaluation point is seen by two registered cameras")
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3)), {}, _by_name(usable, behind)
    camera_index, point_index, xy = kept.bundle_arrays()
    points = points[np.searchsorted(tracks.point_ids, kept.point_ids)]
    anchor = _anchor_observations(calibration, usable, camera_index, point_index, kept.num_points, options)
    cameras = np.unique(camera_index[anchor])  # a weak camera may have no anchor left
    renumbered = np.searchsorted(cameras, camera_index[anchor])
    points = _refine(R[cameras], t[cameras], K[cameras], renumbered, point_index[anchor], xy[anchor], points,
                     options)
    projected, depth = project(K[camera_index], R[camera_index], t[camera_index], points[point_index])
    in_front = depth > MIN_DEPTH
    behind = behind + np.bincount(camera_index[~in_front], minlength=len(usable))
    error = np.linalg.norm(projected - xy, axis=1)
    errors = {name: error[(camera_index == c) & in_front] for c, name in enumerate(usable)}
    return kept.point_ids, points, errors, _by_name(usable, behind)


def _anchor_observations(calibration: Calibration, usable: list[str], camera_index: np.ndarray,
                         point_index: np.ndarray, num_points: int, options: EvaluationOptions) -> np.ndarray:
    """The observations that place the evaluation points: those of the held-out cameras
    (with ``weak_cameras_place_points`` off, the ones the calibration reports as weak
    too) are left out wherever two others see the point, so that their pose error does
    not move the points every other camera is judged on (they are still judged on them)."""
    def left_out(name: str) -> bool:
        if name in options.held_out:
            return True
        return not options.weak_cameras_place_points and name in calibration.metrics and calibration.metrics[name].weak

    strong = ~np.array([left_out(name) for name in usable], dtype=bool)[camera_index]
    strong_views = np.bincount(point_index[strong], minlength=num_points)
    return strong | (strong_views[point_index] < MIN_VIEWS)


def _by_name(names: list[str], counts: np.ndarray) -> dict[str, int]:
    return {name: int(count) for name, count in zip(names, counts)}


def _refine(R: np.ndarray, t: np.ndarray, K: np.ndarray, camera_index: np.ndarray, point_index: np.ndarray,
            xy: np.ndarray, points: np.ndarray, options: EvaluationOptions) -> np.ndarray:
    """Bundle adjustment of the points with the poses fixed (calibproj._core.ba)."""
    import cv2

    from calibproj import _core

    if len(xy) == 0:
        return points
    poses = np.array([np.concatenate([cv2.Rodrigues(R_c)[0].ravel(), t_c]) for R_c, t_c in zip(R, t)])
    result = _core.ba.bundle_adjust(
        camera_index.astype(np.int32), point_index.astype(np.int32), xy, K, poses, points,
        model="free", loss=options.loss, loss_scale=options.loss_scale_px, max_iterations=options.max_iterations,
        num_threads=options.num_threads, refine_poses=False,
    )
    logger.info("evaluation points refined: cost %.6g -> %.6g in %d iterations", result.initial_cost,
                result.final_cost, result.iterations)
    return np.asarray(result.points, dtype=float).reshape(-1, 3)


def normalised_rays(K: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Pinhole normalised coordinates ``K^-1 [u, v, 1]`` (first two), per observation; K is ``(N, 3, 3)``."""
    return (xy - K[:, :2, 2]) / np.stack([K[:, 0, 0], K[:, 1, 1]], axis=1)


def triangulate_tracks(R: np.ndarray, t: np.ndarray, camera_index: np.ndarray, point_index: np.ndarray,
                       rays: np.ndarray, num_points: int, initialisation: str = "pair") -> np.ndarray:
    """First estimate of every point (every point must have two views at least): the
    C++ linear triangulation, from the point's best pair of views or from all of them."""
    from calibproj import _core

    used = np.arange(len(point_index))
    if initialisation == "pair":
        order = np.argsort(point_index, kind="stable")
        starts = np.searchsorted(point_index[order], np.arange(num_points + 1))
        pairs = []
        for p in range(num_points):
            views = order[starts[p]:starts[p + 1]]
            pairs.extend(views[list(best_pair(R[camera_index[views]], rays[views]))])
        used = np.array(pairs, dtype=np.int64)
    cameras = camera_index[used]
    return _core.geometry.triangulate_linear(R[cameras], t[cameras], rays[used], point_index[used], num_points)


def best_pair(R: np.ndarray, rays: np.ndarray) -> tuple[int, int]:
    """The two views whose world rays meet at the angle closest to 90 degrees.

    The uncertainty of a two-view triangulation grows as 1 / sin(angle), so rays
    nearly parallel or nearly opposite are both poor; the largest sine is best.
    """
    directions = np.einsum("nji,nj->ni", R, np.column_stack([rays, np.ones(len(rays))]))  # R^T [x, y, 1]
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    sines = np.linalg.norm(np.cross(directions[:, None, :], directions[None, :, :]), axis=2)
    a, b = np.unravel_index(int(np.argmax(np.triu(sines, k=1))), sines.shape)
    return int(a), int(b)


# -- per-camera results ---------------------------------------------------------------------


def _camera_results(calibration: Calibration, tracks: Tracks, errors: dict[str, np.ndarray],
                    behind: dict[str, int], unusable: dict[str, str]) -> dict[str, CameraEvaluation]:
    names = list(dict.fromkeys([*calibration.metrics, *calibration.poses, *calibration.failed,
                                *tracks.camera_names]))
    cameras = {}
    for name in names:
        camera_errors = errors.get(name, np.zeros(0))
        failure = _failure(calibration, tracks, unusable, name, len(camera_errors))
        if behind.get(name):
            logger.warning("camera %s: %d evaluation points triangulated behind it; its pose is suspect",
                           name, behind[name])
        if failure:
            cameras[name] = CameraEvaluation(None, None, 0, failure, behind.get(name, 0))
        else:
            cameras[name] = CameraEvaluation(float(np.mean(camera_errors)), float(np.std(camera_errors)),
                                             len(camera_errors), None, behind.get(name, 0))
    return cameras


def _failure(calibration: Calibration, tracks: Tracks, unusable: dict[str, str], name: str,
             count: int) -> str | None:
    if name in calibration.failed:
        return f"not registered: {calibration.failed[name]}"
    if name not in calibration.poses:
        return "not in the calibration"
    if name not in tracks.camera_names:
        return "not in the evaluation data"
    if name in unusable:
        return f"no usable intrinsics: {unusable[name]}"
    if count == 0:
        return "no evaluation point seen by this camera and another registered one"
    return None


def _threshold_key(threshold: float) -> str:
    """``0.5 -> "0.5"``, ``2.0 -> "2"`` (the keys of ``evaluate --json``)."""
    return f"{threshold:g}"
