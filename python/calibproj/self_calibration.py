"""Self-calibration: each camera's focal length and lens distortion from the projection.

The projected floor points seen by several cameras determine the cameras' intrinsics
as well as their poses (planar self-calibration: the floor's circular points are shared
by every camera, so each tilted view constrains its camera's focal length, and rows of
markers that are straight on the floor constrain the distortion). This stage takes a
calibration made with nominal intrinsics and refines, in one Ceres problem, the poses,
the floor points and the requested lens entries of every registered camera, from the
raw (distorted) pixels (``calibproj._core.selfcal``: analytic Jacobians).

Observability comes from the covariance of the solution: a requested group of entries
(focal length, principal point, distortion) that the data do not determine, e.g. for
a camera looking nearly straight down or zoomed onto a small patch of floor, keeps its
given values and is reported; the others are solved again with it held.

Entries (``--refine-intrinsics``): ``focal`` (fx and fy together, their ratio kept),
``pp`` (cx, cy), ``k1``, ``k2``, ``k3``, ``tangential`` (p1, p2); ``none``. The model
refined is OpenCV's 5-coefficient one; a camera whose given distortion has more
coefficients in use is refused.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any

import cv2
import numpy as np

from calibproj import _core
from calibproj.calibration import Calibration
from calibproj.io.intrinsics import Intrinsics, image_size, intrinsics_from_json
from calibproj.io.jsonio import FormatError, read_json, write_json
from calibproj.tracks import Tracks

logger = logging.getLogger(__name__)

# Entries of a lens block, in the order of calibproj._core.selfcal.
LENS_ENTRIES = ("focal", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
LENS_SIZE = len(LENS_ENTRIES)
# Names a user gives, the lens entries each stands for and the group it belongs to.
REFINABLE = {
    "focal": ((0,), "focal"),
    "pp": ((1, 2), "principal point"),
    "k1": ((3,), "distortion"),
    "k2": ((4,), "distortion"),
    "k3": ((7,), "distortion"),
    "tangential": ((5, 6), "distortion"),
}
GROUPS = ("focal", "principal point", "distortion")
# Entries are freed in stages, each kept only if the data determine it: the most
# robust first; a free principal point, k3 and tangential terms make a partial view's
# problem ill-conditioned and are tried last.
STAGES = (("focal", "k1"), ("k2",), ("k3",), ("tangential",), ("pp",))
# Entries a camera may free only when its observations reach far enough towards the
# image corners: fitted on a central patch they do not hold in the rest of the image.
NEEDS_COVERAGE = ("k3", "pp")
ALL_CAMERAS = "*"
DISTORTION_ENTRIES = (3, 4, 5, 6, 7)


@dataclass(frozen=True)
class RefineRequest:
    """Which lens entries to refine, per camera (``ALL_CAMERAS`` for the rest)."""

    entries: Mapping[str, tuple[str, ...]]

    @classmethod
    def parse(cls, values: str | Sequence[str]) -> RefineRequest:
        """From ``"focal,k1,k2"`` (every camera) and/or ``"CAMERA=focal,k1"`` items;
        ``"CAMERA=none"`` holds that camera. ValueError naming the bad item."""
        items = [values] if isinstance(values, str) else list(values)
        entries: dict[str, tuple[str, ...]] = {}
        for item in items:
            camera, _, names = item.rpartition("=")
            camera = camera.strip() or ALL_CAMERAS
            chosen = tuple(dict.fromkeys(n.strip() for n in names.split(",") if n.strip()))
            if not chosen:
                raise ValueError(f"--refine-intrinsics {item!r}: no entry named (use e.g. focal,k1,k2)")
            if chosen == ("none",):
                chosen = ()
            elif "none" in chosen:
                raise ValueError(f"--refine-intrinsics {item!r}: 'none' stands alone (CAMERA=none holds that "
                                 f"camera's intrinsics)")
            unknown = [n for n in chosen if n not in REFINABLE]
            if unknown:
                raise ValueError(f"--refine-intrinsics {item!r}: unknown entry {unknown[0]!r} "
                                 f"(known: {', '.join(REFINABLE)}, none)")
            if camera in entries:
                raise ValueError(f"--refine-intrinsics: camera {camera!r} given twice")
            entries[camera] = chosen
        return cls(entries)

    def of(self, camera: str) -> tuple[str, ...]:
        return self.entries.get(camera, self.entries.get(ALL_CAMERAS, ()))

    def cameras_named(self) -> list[str]:
        return [name for name in self.entries if name != ALL_CAMERAS]

    def check_cameras(self, camera_names: Sequence[str]) -> None:
        """ValueError when the request names a camera that is not among ``camera_names``."""
        unknown = [name for name in self.cameras_named() if name not in camera_names]
        if unknown:
            raise ValueError(f"--refine-intrinsics: no camera named {unknown[0]!r} "
                             f"(cameras: {', '.join(camera_names) or 'none'})")


@dataclass
class SelfCalibrationOptions:
    """Knobs of the self-calibration.

    Attributes:
        max_focal_sigma: the focal length counts as determined when its 1-sigma
            uncertainty is at most this share of it.
        max_principal_point_sigma_px: the principal point counts as determined when the
            1-sigma uncertainty of cx and cy is at most this many pixels (or the camera's
            noise, if larger).
        max_distortion_sigma_px: the distortion counts as determined when the 1-sigma
            uncertainty of the displacement it causes, RMS over the points the camera saw
            (elsewhere in the image nothing measured it), is at most this many pixels (or
            distortion_sigma_noise_ratio times the camera's noise, if larger).
        distortion_sigma_noise_ratio: see max_distortion_sigma_px; the noise is the RMS
            of one residual coordinate.
        min_chi2_drop: an entry is kept only if freeing it lowers its camera's sum of
            squared residuals by at least this many times the camera's noise variance, so
            that entries which only fit noise stay held (10: about the Bayesian information
            criterion's ln(n) for the few thousand residuals of a camera; at 25 the small
            tangential terms of wide lenses were left out and biased the poses).
        first_loss_scale_px: Cauchy scale of the first solve, whose start may be far
            off (tens of pixels at the image corners).
        outlier_gate_px: after the first solve an observation is kept when its residual
            is below this many pixels or outlier_gate_sigma_factor times its camera's
            robust noise, whichever is larger.
        outlier_gate_sigma_factor: see outlier_gate_px.
        lens_solver_iterations: iterations of each Ceres solve.
        rounds: self-calibrations, each followed by a registration with its intrinsics;
            the second starts where the first left off, from all the observations
            (the first registration, with the given intrinsics, may have left many out).
        min_coverage: k3 and pp are freed only for a camera whose
            observations reach at least this share of the way from the principal point
            to the farthest image corner (95th percentile).
        max_sampled_points: observations per camera where the distortion's uncertainty
            is sampled.
    """

    max_focal_sigma: float = 0.01
    max_principal_point_sigma_px: float = 1.0
    max_distortion_sigma_px: float = 0.3
    distortion_sigma_noise_ratio: float = 2.0
    min_chi2_drop: float = 10.0
    first_loss_scale_px: float = 2.0
    outlier_gate_px: float = 3.0
    outlier_gate_sigma_factor: float = 4.0
    lens_solver_iterations: int = 200
    max_sampled_points: int = 500
    closed_form_min_change: float = 0.1
    rounds: int = 2
    min_coverage: float = 0.5

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise ValueError(f"self-calibration option {f.name} must be a positive number, got {value!r}")


@dataclass
class LensReport:
    """What the self-calibration did to one camera."""

    camera: str
    requested: list[str]
    refined: list[str] = field(default_factory=list)  # entries changed from the given values
    held: dict[str, str] = field(default_factory=dict)  # entry -> why its given value was kept
    focal_sigma: float | None = None  # pixels
    principal_point_sigma_px: float | None = None
    distortion_sigma_px: float | None = None  # worst over the image
    noise_px: float | None = None  # RMS of one residual coordinate
    coverage: float | None = None  # how far towards the image corners the observations reach (0-1)
    left_out: bool = False  # its focal length not determined, its observations left out of the solve
    observations: int = 0
    given: dict[str, float] = field(default_factory=dict)
    result: dict[str, float] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class LensCovariance:
    """How the refined lenses of ``cameras`` err, together: their joint covariance
    ``matrix`` (8n, 8n) over ``LENS_ENTRIES``, the k-th camera in rows and columns 8k to
    8k + 7, zero outside the refined entries, in pixels of each camera's measured noise.
    Lenses fitted to the same floor points err together: the off-diagonal blocks say how."""

    cameras: tuple[str, ...] = ()
    matrix: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    def of(self, name: str) -> np.ndarray:
        """The covariance (8, 8) of camera ``name``'s lens."""
        return self.among([name])

    def among(self, names: Sequence[str]) -> np.ndarray:
        """The joint covariance (8n, 8n) of these cameras' lenses, in their order."""
        rows = np.array([LENS_SIZE * self.cameras.index(name) + i for name in names for i in range(LENS_SIZE)],
                        dtype=int)
        return self.matrix[np.ix_(rows, rows)]


@dataclass
class SelfCalibration:
    """Refined intrinsics (every camera of the input; unchanged where nothing was refined),
    one report per camera that was asked for, and the joint covariance of the lenses it
    refined, which the registration takes into the poses'."""

    intrinsics: dict[str, Intrinsics]
    reports: dict[str, LensReport]
    lens_covariance: LensCovariance = field(default_factory=LensCovariance)


def check_request(request: RefineRequest, intrinsics: Mapping[str, Intrinsics],
                  camera_names: Sequence[str]) -> dict[str, str]:
    """Cameras whose lens cannot be refined, with the reason (named in the request but
    unknown cameras raise ValueError)."""
    request.check_cameras(camera_names)
    refused = {}
    for name in camera_names:
        if request.of(name) and name in intrinsics:
            dist = intrinsics[name].dist
            if dist.size > 5 and np.any(dist[5:] != 0.0):
                refused[name] = (f"its distortion uses {dist.size} coefficients; self-calibration refines "
                                 "OpenCV's 5-coefficient model (k1, k2, p1, p2, k3)")
    return refused


def self_calibrate(tracks: Tracks, intrinsics: Mapping[str, Intrinsics], calibration: Calibration,
                   request: RefineRequest, options: SelfCalibrationOptions | None = None,
                   num_threads: int = 1, given: Mapping[str, Intrinsics] | None = None,
                   earlier: Mapping[str, LensReport] | None = None) -> SelfCalibration:
    """Refine the requested lens entries of the registered cameras of ``calibration``.

    ``tracks`` are undistorted with ``intrinsics``, where the refinement starts; an entry
    held keeps its value in ``given`` (default: ``intrinsics``). A later round passes the
    first round's result as ``intrinsics``, the user's values as ``given`` and the first
    round's reports as ``earlier``: the entries it chose are refined again, from the
    registration its intrinsics allowed, without choosing anew. The result's intrinsics
    are to be used with tracks converted by ``convert_tracks``.
    """
    options = options or SelfCalibrationOptions()
    given = intrinsics if given is None else given
    refused = check_request(request, given, tracks.camera_names)
    problem = _Problem.build(tracks, intrinsics, calibration, request, refused, given)
    reports = {name: LensReport(name, list(request.of(name)), given=_lens_dict(problem.given[c]))
               for c, name in enumerate(problem.cameras) if request.of(name)}
    for name, reason in refused.items():
        reports[name] = LensReport(name, list(request.of(name)), held={entry: reason for entry in request.of(name)})
    if problem.empty:
        return SelfCalibration(dict(intrinsics), reports)
    solve = {"max_iterations": options.lens_solver_iterations, "num_threads": num_threads}
    if earlier is not None:
        solution = _refine_again(problem, earlier, options, reports, solve)
    else:
        solution = _choose_and_refine(problem, options, reports, solve)
    solution = _hold_undetermined(problem, solution, options, reports, solve)
    if solution is not None and problem.hold_at_given():  # a later round held an entry the first one had moved
        solution = problem.solve(loss="none", loss_scale=1.0, **solve)
    refined = _refined_intrinsics(problem, solution, intrinsics, given, reports, refused)
    return SelfCalibration(refined, reports, _lens_covariances(problem, solution, reports, refused))


def _lens_covariances(problem: _Problem, solution: _core.selfcal.Result | None, reports: Mapping[str, LensReport],
                      refused: Mapping[str, str]) -> LensCovariance:
    """The joint covariance of every lens the solution refined."""
    if solution is None:
        return LensCovariance()
    chosen = [c for c, name in enumerate(problem.cameras)
              if problem.refine[c] and name in reports and name not in refused]
    every = LensCovariance(tuple(problem.cameras), np.asarray(solution.lens_covariance))
    names = [problem.cameras[c] for c in chosen]
    return LensCovariance(tuple(names), every.among(names))


def _refined_intrinsics(problem: _Problem, solution: _core.selfcal.Result | None, intrinsics: Mapping[str, Intrinsics],
                        given: Mapping[str, Intrinsics], reports: dict[str, LensReport],
                        refused: Mapping[str, str]) -> dict[str, Intrinsics]:
    """Every camera's intrinsics after the refinement, the reports completed."""
    if solution is None:  # every other camera left out: nothing to refine these against
        for c, name in enumerate(problem.cameras):
            for entry in reports[name].requested if name in reports else ():
                reports[name].held.setdefault(entry, "not determined: the other cameras' lenses are not either, "
                                                     "and one camera alone does not determine its own")
            problem.refine[c] = []
    refined = {name: given[name] if name in problem.dropped else value for name, value in intrinsics.items()}
    for c, name in enumerate(problem.cameras):
        if name not in reports or name in refused:
            continue
        lens = solution.lenses[c] if solution is not None and problem.refine[c] else problem.given[c]
        refined[name] = _intrinsics_of(given[name], lens)
        report = reports[name]
        report.refined = [entry for entry in report.requested if entry not in report.held]
        report.result = _lens_dict(lens)
        report.noise_px = float(solution.noise_px[c]) if solution is not None else None
        report.observations = int(np.sum(problem.camera_index == c))
        _log_report(report)
    for name, observations in problem.dropped.items():
        reports[name].refined = []
        reports[name].result = reports[name].given
        reports[name].observations = observations
        _log_report(reports[name])
    return refined


def _choose_and_refine(problem: _Problem, options: SelfCalibrationOptions, reports: dict[str, LensReport],
                       solve: dict[str, Any]) -> _core.selfcal.Result:
    """Frees the requested entries stage by stage, keeping those that earn their place."""
    # A first robust solve with the first two stages' entries brings the residuals near the
    # noise, so that gross outliers can be told apart; the stages then start over.
    problem.refine = problem.stage_entries(STAGES[0] + STAGES[1], [[] for _ in problem.cameras])
    problem.gate(problem.solve(loss="cauchy", loss_scale=options.first_loss_scale_px, **solve), options)
    problem.refine = [[] for _ in problem.cameras]
    problem.lenses = problem.start.copy()
    solution = problem.solve(loss="none", loss_scale=1.0, **solve)
    for stage in STAGES:
        solution = _run_stage(problem, stage, solution, options, reports, solve)
    return solution


def _refine_again(problem: _Problem, earlier: Mapping[str, LensReport], options: SelfCalibrationOptions,
                  reports: dict[str, LensReport], solve: dict[str, Any]) -> _core.selfcal.Result | None:
    """Refines the entries an earlier round chose, from where it left off."""
    for c, name in reversed(list(enumerate(problem.cameras))):
        before = earlier.get(name)
        if name in reports and before is not None:
            reports[name].held.update(before.held)
            reports[name].coverage = before.coverage
            reports[name].focal_sigma = before.focal_sigma
            problem.refine[c] = sorted(k for entry in before.refined for k in REFINABLE[entry][0])
            if before.left_out:
                reports[name].left_out = True
                problem.drop_camera(c)
    if not problem.solvable:
        return None
    problem.gate(problem.solve(loss="cauchy", loss_scale=options.first_loss_scale_px, **solve), options)
    return problem.solve(loss="none", loss_scale=1.0, **solve)


def _run_stage(problem: _Problem, stage: tuple[str, ...], solution: _core.selfcal.Result,
               options: SelfCalibrationOptions, reports: dict[str, LensReport],
               solve: dict[str, Any]) -> _core.selfcal.Result:
    """Frees the stage's requested entries and solves; a camera whose fit they do not
    improve significantly gets them held at their given values and the stage starts
    over from where it began. Returns the last solution."""
    before = problem.refine
    start = (problem.poses.copy(), problem.points.copy(), problem.lenses.copy())
    rejected = {c for c in range(len(problem.cameras))
                if _hold_for_coverage(problem, c, stage, options, reports.get(problem.cameras[c]))}
    while True:
        problem.refine = problem.stage_entries(stage, before, rejected)
        if problem.refine == before:
            return solution  # nothing (left) to free: the state is the one it began with
        attempt = problem.solve(loss="none", loss_scale=1.0, **solve)
        failing = {}
        for c, name in enumerate(problem.cameras):
            if problem.refine[c] != before[c]:
                failing[c] = problem.insignificant(c, solution, attempt, len(problem.refine[c]) - len(before[c]),
                                                   options)
        failing = {c: why for c, why in failing.items() if why}
        if not failing:
            return attempt
        for c, why in failing.items():
            rejected.add(c)
            for entry in stage:
                if entry in reports[problem.cameras[c]].requested:
                    reports[problem.cameras[c]].held[entry] = why
        problem.poses, problem.points, problem.lenses = (a.copy() for a in start)


def _hold_for_coverage(problem: _Problem, c: int, stage: tuple[str, ...], options: SelfCalibrationOptions,
                       report: LensReport | None) -> bool:
    """Whether camera ``c`` may not free the stage's entries because its observations
    do not reach far enough towards the image corners (recorded in ``report``)."""
    coverage = problem.coverage(c)
    if report is not None:
        report.coverage = coverage
    asked = [entry for entry in stage if entry in NEEDS_COVERAGE and entry in problem.requested[c]]
    if not asked or coverage >= options.min_coverage:
        return False
    for entry in asked:
        report.held[entry] = (f"the floor reaches only {coverage:.0%} of the way to the image corners "
                              f"(at least {options.min_coverage:.0%} needed): fitted there, it would not hold "
                              "in the rest of the image")
    return True


def _hold_undetermined(problem: _Problem, solution: _core.selfcal.Result | None, options: SelfCalibrationOptions,
                       reports: dict[str, LensReport], solve: dict[str, Any]) -> _core.selfcal.Result | None:
    """Holds at its given values the group whose uncertainty exceeds its limit the most
    (over every camera), solves again, and repeats until every group left is determined:
    one at a time, since holding one may determine the others (three cameras do not
    determine three focal lengths; with one of them known they do). A camera whose
    focal length is held is left out of the problem. Returns the last solution."""
    while solution is not None and problem.solvable:
        worst = None
        for c, name in enumerate(problem.cameras):
            if problem.refine[c]:
                why, group, excess = problem.undetermined(c, solution, options, reports[name])
                if group is not None and (worst is None or excess > worst[3]):
                    worst = (c, why, group, excess)
        if worst is None:
            return solution
        c, why, group, _ = worst
        name = problem.cameras[c]
        entries = [entry for entry in reports[name].requested if group == "focal" or REFINABLE[entry][1] == group]
        for entry in entries:
            reports[name].held.setdefault(entry, why)
        lens_entries = [k for entry in entries for k in REFINABLE[entry][0]]
        problem.refine[c] = [k for k in problem.refine[c] if k not in lens_entries]
        problem.lenses[c, lens_entries] = problem.given[c, lens_entries]
        if group == "focal":  # nothing of this lens can be trusted: all of it is held, and left out
            reports[name].left_out = True
            problem.drop_camera(c)
        solution = problem.solve(loss="none", loss_scale=1.0, **solve) if problem.solvable else None
    return solution


def closed_form_start(tracks: Tracks, intrinsics: Mapping[str, Intrinsics], calibration: Calibration,
                      request: RefineRequest, options: SelfCalibrationOptions) -> dict[str, Intrinsics]:
    """Intrinsics to start the refinement from: the given ones, but for a camera whose
    focal length is to be refined and disagrees by more than
    ``options.closed_form_min_change`` with the closed-form planar autocalibration
    (``calibproj.planar_autocalibration``), that one. Cameras whose focal length is not
    refined count as known."""
    from calibproj.planar_autocalibration import MIN_POINTS, focal_lengths

    lookup = {int(i): row for row, i in enumerate(calibration.point_ids)}
    homographies, known = {}, {}
    for name in calibration.poses:
        if name not in intrinsics or name not in tracks.camera_names:
            continue
        ids, xy = tracks.observations(name)
        rows = np.array([lookup.get(int(i), -1) for i in ids], dtype=np.int64)
        if np.sum(rows >= 0) < MIN_POINTS:
            continue
        floor = calibration.points[rows[rows >= 0], :2]
        centred = xy[rows >= 0] - intrinsics[name].K[:2, 2]
        H, _ = cv2.findHomography(floor, centred, cv2.RANSAC, 3.0)
        if H is None:
            continue
        homographies[name] = H
        if "focal" not in request.of(name):
            known[name] = float(np.sqrt(intrinsics[name].K[0, 0] * intrinsics[name].K[1, 1]))
    try:
        found = focal_lengths(homographies, known)
    except ValueError as error:
        logger.info("closed-form focal lengths not available (%s); starting from the given ones", error)
        return dict(intrinsics)
    start = dict(intrinsics)
    for name, focal in found.focal.items():
        given = intrinsics[name].K[0, 0]
        if abs(focal / given - 1.0) > options.closed_form_min_change:
            logger.info("camera %s: starting from the closed-form focal length %.1f px (given %.1f px)",
                        name, focal, given)
            start[name] = _intrinsics_of(intrinsics[name], np.r_[focal, _lens_of(intrinsics[name])[1:]])
    return start


def nominal_intrinsics(name: str, resolution: tuple[int, int], fov_deg: float) -> Intrinsics:
    """A pinhole with the horizontal field of view ``fov_deg``, square pixels, the
    principal point at the image centre and no distortion: where a camera without any
    calibration starts."""
    width, height = resolution
    focal = 0.5 * width / np.tan(np.radians(fov_deg) / 2.0)
    K = np.array([[focal, 0.0, (width - 1) / 2.0], [0.0, focal, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
    return Intrinsics(name, (width, height), K, np.zeros(5))


def convert_tracks(tracks: Tracks, given: Mapping[str, Intrinsics], refined: Mapping[str, Intrinsics]) -> Tracks:
    """Tracks undistorted with ``given`` re-expressed as undistorted with ``refined``."""
    xy = tracks.xy.copy()
    for c, name in enumerate(tracks.camera_names):
        if name not in given or name not in refined or given[name] is refined[name]:
            continue
        rows = tracks.camera_index == c
        xy[rows] = refined[name].undistort_points(given[name].distort_points(tracks.xy[rows]))
    return replace(tracks, xy=xy)


@dataclass
class _Problem:
    """The arrays of ``_core.selfcal.self_calibrate`` and which entries move."""

    cameras: list[str]
    camera_index: np.ndarray
    point_index: np.ndarray
    observed: np.ndarray
    given: np.ndarray  # (C, 8) lenses as given: where held entries stay
    start: np.ndarray  # (C, 8) lenses the refinement starts from
    shapes: np.ndarray
    refine: list[list[int]]
    poses: np.ndarray
    points: np.ndarray
    lenses: np.ndarray  # (C, 8) current values
    image_sizes: list[tuple[float, float]]
    requested: list[tuple[str, ...]]  # per camera, entry names asked for
    dropped: dict[str, int] = field(default_factory=dict)  # camera -> its observations


    @property
    def solvable(self) -> bool:
        return len(self.cameras) > 0 and len(self.points) >= 2 and len(self.camera_index) > 0

    @property
    def empty(self) -> bool:
        return len(self.camera_index) == 0 or not any(self.requested)

    def hold_at_given(self) -> bool:
        """Puts every entry not refined back to its given value; True if one moved."""
        moved = False
        for c in range(len(self.cameras)):
            held = ~np.isin(np.arange(8), self.refine[c])
            if np.any(self.lenses[c, held] != self.given[c, held]):
                self.lenses[c, held] = self.given[c, held]
                moved = True
        return moved

    @classmethod
    def build(cls, tracks: Tracks, intrinsics: Mapping[str, Intrinsics], calibration: Calibration,
              request: RefineRequest, refused: Mapping[str, str], given: Mapping[str, Intrinsics]) -> _Problem:
        cameras = [n for n in tracks.camera_names if n in calibration.poses and n in intrinsics]
        kept = tracks.keep_cameras(cameras).with_min_track_length(2) if cameras else Tracks.empty([])
        cameras = list(kept.camera_names)
        camera_index, point_index, xy = kept.bundle_arrays()
        observed = xy.copy()
        for c, name in enumerate(cameras):
            rows = camera_index == c
            observed[rows] = intrinsics[name].distort_points(xy[rows])
        poses = np.array([_pose_vector(*calibration.poses[n]) for n in cameras]).reshape(-1, 6)
        points = _floor_points(kept, intrinsics, calibration)
        requested = [() if name in refused else request.of(name) for name in cameras]
        start = np.array([_lens_of(intrinsics[n]) for n in cameras]).reshape(-1, 8)
        return cls(cameras, camera_index.astype(np.int32), point_index.astype(np.int32), observed,
                   np.array([_lens_of(given[n]) for n in cameras]).reshape(-1, 8), start,
                   np.array([[i.K[1, 1] / i.K[0, 0], i.K[0, 1] / i.K[0, 0]] for i in map(intrinsics.get, cameras)]
                            ).reshape(-1, 2),
                   [[] for _ in cameras], poses, points, start.copy(), [image_size(intrinsics[n]) for n in cameras],
                   requested)

    def solve(self, **kwargs: Any) -> _core.selfcal.Result:
        solution = _core.selfcal.self_calibrate(self.camera_index, self.point_index, self.observed, self.lenses,
                                                self.shapes, self.refine, self.poses, self.points, **kwargs)
        # Copies: the result's arrays are read-only views of it, and the problem's move on.
        self.lenses, self.poses, self.points = (np.array(a) for a in (solution.lenses, solution.poses, solution.points))
        return solution

    def gate(self, solution: _core.selfcal.Result, options: SelfCalibrationOptions) -> None:
        """Keeps the observations within the gate of their camera's noise, and the
        points still seen twice."""
        error = np.linalg.norm(solution.residuals, axis=1)
        noise = solution.noise_px
        keep = np.isfinite(error)
        for c in range(len(self.cameras)):
            rows = self.camera_index == c
            inliers = error[rows & keep]
            sigma = 1.4826 * np.median(inliers) / np.sqrt(2.0) if len(inliers) else noise[c]
            keep &= ~rows | (error < max(options.outlier_gate_px, options.outlier_gate_sigma_factor * sigma))
        self._keep(keep)

    def _keep(self, keep: np.ndarray) -> None:
        """Keeps the observations ``keep`` selects and the points they still show twice."""
        seen = np.bincount(self.point_index[keep], minlength=len(self.points))
        keep = keep & (seen[self.point_index] >= 2)
        used = np.unique(self.point_index[keep])
        remap = np.full(len(self.points), -1, dtype=np.int32)
        remap[used] = np.arange(len(used), dtype=np.int32)
        self.camera_index, self.observed = self.camera_index[keep], self.observed[keep]
        self.point_index = remap[self.point_index[keep]]
        self.points = self.points[used]

    def drop_camera(self, c: int) -> None:
        """Takes camera ``c`` out of the problem: its focal length is not determined, and
        with a wrong one its observations would strain the others' lenses."""
        self.dropped[self.cameras[c]] = int(np.sum(self.camera_index == c))
        keep = self.camera_index != c
        self.camera_index = np.where(self.camera_index > c, self.camera_index - 1, self.camera_index).astype(np.int32)
        self._keep(keep)
        del self.cameras[c], self.refine[c], self.requested[c], self.image_sizes[c]
        self.given, self.start, self.lenses, self.shapes, self.poses = (
            np.delete(a, c, axis=0) for a in (self.given, self.start, self.lenses, self.shapes, self.poses))

    def coverage(self, camera: int) -> float:
        """How far the camera's observations reach from the principal point towards the
        farthest image corner (95th percentile of their radius over the corner's)."""
        rows = self.camera_index == camera
        centre = self.lenses[camera, 1:3]
        width, height = self.image_sizes[camera]
        corners = np.array([[0.0, 0.0], [width - 1, 0.0], [0.0, height - 1], [width - 1, height - 1]])
        corner = np.linalg.norm(corners - centre, axis=1).max()
        radius = np.linalg.norm(self.observed[rows] - centre, axis=1)
        return float(np.percentile(radius, 95) / corner) if len(radius) else 0.0

    def seen(self, camera: int, count: int) -> np.ndarray:
        """Normalised coordinates (pinhole) of up to ``count`` of the camera's observations."""
        rows = np.flatnonzero(self.camera_index == camera)
        rows = rows[:: max(1, len(rows) // count)]
        R = cv2.Rodrigues(self.poses[camera, :3])[0]
        in_camera = self.points[self.point_index[rows]] @ R[:, :2].T + self.poses[camera, 3:]
        return in_camera[:, :2] / in_camera[:, 2:]

    def stage_entries(self, stage: tuple[str, ...], before: list[list[int]],
                      rejected: set[int] = frozenset()) -> list[list[int]]:
        """Per camera, the entries refined with the stage's requested ones added (not for
        cameras in ``rejected``)."""
        out = []
        for c, entries in enumerate(before):
            added = [] if c in rejected else [k for name in stage if name in self.requested[c]
                                               for k in REFINABLE[name][0]]
            out.append(sorted(set(entries) | set(added)))
        return out

    def insignificant(self, c: int, before: _core.selfcal.Result, after: _core.selfcal.Result, added: int,
                      options: SelfCalibrationOptions) -> str | None:
        """Why the entries just freed do not earn their place for camera ``c`` (its
        residuals, in units of its noise, fell by less than ``min_chi2_drop`` per entry),
        or None. Without this test an entry that only fits noise would be kept."""
        rows = self.camera_index == c
        variance = float(after.noise_px[c]) ** 2
        drop = (np.nansum(before.residuals[rows] ** 2) - np.nansum(after.residuals[rows] ** 2)) / variance
        if drop >= options.min_chi2_drop * added:
            return None
        return (f"does not improve the fit: the residuals fell by {max(drop, 0.0):.1f} noise variances, "
                f"less than {options.min_chi2_drop:g} per entry")

    def undetermined(self, c: int, solution: _core.selfcal.Result, options: SelfCalibrationOptions,
                     report: LensReport) -> tuple[str, str | None, float]:
        """The group of camera ``c``'s refined lens that the data determine worst, if
        beyond its limit, with why and by how much: ``(why, group, sigma / limit)``, or
        ``("", None, 0)``; records the groups' uncertainties in ``report``."""
        lens = solution.lenses[c]
        sigmas = _group_sigmas(solution.lens_covariance_of(c, c), lens, self.shapes[c],
                               self.seen(c, options.max_sampled_points))
        report.focal_sigma = sigmas.get("focal", report.focal_sigma)
        report.principal_point_sigma_px = sigmas.get("principal point", report.principal_point_sigma_px)
        report.distortion_sigma_px = sigmas.get("distortion", report.distortion_sigma_px)
        limits = _limits(options, lens[0], float(solution.noise_px[c]))
        excess = {group: sigma / limits[group] for group, sigma in sigmas.items() if sigma > limits[group]}
        if not excess:
            return "", None, 0.0
        group = max(excess, key=excess.get)
        unit = f"px ({sigmas[group] / lens[0]:.2%})" if group == "focal" else "px"
        return (f"not determined by the data: {group} 1 sigma {sigmas[group]:.3g} {unit} "
                f"exceeds {limits[group]:.3g} px", group, excess[group])


def _limits(options: SelfCalibrationOptions, focal: float, noise_px: float) -> dict[str, float]:
    """The largest 1-sigma uncertainty, in pixels, at which each group counts as determined."""
    return {"focal": options.max_focal_sigma * focal,
            "principal point": max(options.max_principal_point_sigma_px, noise_px),
            "distortion": max(options.max_distortion_sigma_px, options.distortion_sigma_noise_ratio * noise_px)}


def _group_sigmas(covariance: np.ndarray, lens: np.ndarray, shape: np.ndarray, seen: np.ndarray) -> dict[str, float]:
    """1 sigma of each refined group: focal (px), principal point (px, worse axis) and
    the distortion's displacement (px, along its worse axis, RMS over ``seen``, the
    normalised coordinates of the camera's observations: elsewhere in the image nothing
    measured it)."""
    variances = np.diag(covariance)
    out = {}
    if variances[0] > 0:
        out["focal"] = float(np.sqrt(variances[0]))
    if variances[1] > 0 or variances[2] > 0:
        out["principal point"] = float(np.sqrt(max(variances[1], variances[2])))
    distortion = np.array(DISTORTION_ENTRIES)
    if np.any(variances[distortion] > 0) and len(seen):
        x, y = seen[:, 0], seen[:, 1]
        r2 = x * x + y * y
        # d(displacement)/d(k1, k2, p1, p2, k3), pixels: (N, 2, 5)
        J = lens[0] * np.stack([np.column_stack([x * r2, x * r2**2, 2 * x * y, r2 + 2 * x * x, x * r2**3]),
                                np.column_stack([y * r2, y * r2**2, r2 + 2 * y * y, 2 * x * y, y * r2**3])], axis=1)
        J[:, 1] *= shape[0]
        block = covariance[np.ix_(distortion, distortion)]
        along_worst_axis = np.linalg.eigvalsh(J @ block @ J.transpose(0, 2, 1))[:, -1]
        out["distortion"] = float(np.sqrt(max(np.mean(along_worst_axis), 0.0)))
    return out


def _pose_vector(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.concatenate([cv2.Rodrigues(np.asarray(R, dtype=float))[0].ravel(), np.asarray(t, dtype=float)])


def _floor_points(tracks: Tracks, intrinsics: Mapping[str, Intrinsics], calibration: Calibration) -> np.ndarray:
    """Floor coordinates of each point of ``tracks``: the calibration's where it has the
    point, else the median of its rays' intersections with the floor z = 0."""
    known = {int(i): row for row, i in enumerate(calibration.point_ids)}
    hits = np.full((len(tracks.xy), 2), np.nan)
    for c, name in enumerate(tracks.camera_names):
        rows = tracks.camera_index == c
        R, t = calibration.poses[name]
        rays = np.column_stack([intrinsics[name].normalize(tracks.xy[rows]), np.ones(rows.sum())]) @ R
        centre = -R.T @ t
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = -centre[2] / rays[:, 2]
        on_floor = centre[:2] + scale[:, None] * rays[:, :2]
        on_floor[~(scale > 0)] = np.nan
        hits[rows] = on_floor
    points = np.zeros((tracks.num_points, 2))
    for p, point_id in enumerate(tracks.point_ids):
        if int(point_id) in known:
            points[p] = calibration.points[known[int(point_id)], :2]
        else:
            points[p] = np.nanmedian(hits[tracks.point_index == p], axis=0)
    return points


def _lens_of(intrinsics: Intrinsics) -> np.ndarray:
    dist = np.zeros(5)
    dist[: min(5, intrinsics.dist.size)] = intrinsics.dist[:5]
    K = intrinsics.K
    return np.array([K[0, 0], K[0, 2], K[1, 2], dist[0], dist[1], dist[2], dist[3], dist[4]])


def _intrinsics_of(given: Intrinsics, lens: np.ndarray) -> Intrinsics:
    scale = lens[0] / given.K[0, 0]
    K = np.array([[lens[0], given.K[0, 1] * scale, lens[1]], [0.0, given.K[1, 1] * scale, lens[2]], [0, 0, 1]])
    return Intrinsics(given.name, given.resolution, K, lens[[3, 4, 5, 6, 7]])


def _lens_dict(lens: np.ndarray) -> dict[str, float]:
    return {name: float(value) for name, value in zip(LENS_ENTRIES, lens)}


def _log_report(report: LensReport) -> None:
    given, result = report.given, report.result
    change = 100.0 * (result["focal"] / given["focal"] - 1.0) if given and result else 0.0
    logger.info("camera %s: intrinsics refined (%s): focal %.2f -> %.2f px (%+.2f %%, 1 sigma %s px), "
                "k1 %.4f -> %.4f, noise %.3f px%s", report.camera, ", ".join(report.refined) or "nothing",
                given["focal"], result["focal"], change,
                "-" if report.focal_sigma is None else f"{report.focal_sigma:.3g}", given["k1"], result["k1"],
                report.noise_px or 0.0,
                "".join(f"; {group} held: {why}" for group, why in report.held.items()))


SCHEMA_KIND = "self_calibration"
SCHEMA_MAJOR = 1
FILE_NAME = "self_calibration.json"


def write_self_calibration(path: str | os.PathLike, result: SelfCalibration, given: Mapping[str, Intrinsics],
                           options: SelfCalibrationOptions) -> None:
    """``self_calibration.json``: per camera what was refined or held and why, the
    uncertainties, and the intrinsics given (tracks undistorted with them are converted
    by ``convert_tracks``)."""
    cameras = {}
    for name, report in result.reports.items():
        entry = report.to_json()
        if name in given and given[name].resolution is not None:
            entry["given_intrinsics"] = given[name].to_json()
        cameras[name] = entry
    write_json(path, SCHEMA_KIND, SCHEMA_MAJOR, {"options": asdict(options), "cameras": cameras})


def read_given_intrinsics(path: str | os.PathLike) -> dict[str, Intrinsics]:
    """The intrinsics given to the self-calibration of a results folder's
    ``self_calibration.json`` (FormatError naming the file and entry)."""
    document = read_json(path, SCHEMA_KIND, SCHEMA_MAJOR)
    cameras = document.get("cameras")
    if not isinstance(cameras, dict):
        raise FormatError(f"{path}: cameras: expected an object {{name: report}}")
    out = {}
    for name, entry in cameras.items():
        if not isinstance(entry, dict):
            raise FormatError(f"{path}: cameras.{name}: expected an object")
        if entry.get("given_intrinsics") is not None:
            out[name] = intrinsics_from_json(entry["given_intrinsics"], name, f"{path}: cameras.{name}.given_intrinsics")
    return out
