"""The Python driver of the incremental registration (paper section 2.2).

Every algorithmic step is one C++ method of ``calibproj._core.registration.Reconstruction``;
this driver owns the tracks, calls those steps in the order of the C++ ``run()``, logs
each camera as it is added, and yields after every step so that a caller can watch,
hook in, or stop::

    driver = RegistrationDriver(tracks, intrinsics)
    for step in driver.steps():
        print(step.name, step.camera, step.result)
    calibration = driver.result()

``register(tracks, intrinsics)`` does all of it and returns a ``Calibration``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Mapping
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from calibproj import _core
from calibproj.formats.calibration import Calibration
from calibproj.formats.intrinsics import Intrinsics
from calibproj.common.option_tables import options_class
from calibproj.formats.tracks import Tracks

if TYPE_CHECKING:
    from calibproj.sequence.projected import ProjectedMarkers
    from calibproj.selfcal.lenses import LensCovariance

logger = logging.getLogger(__name__)


def _check_options(self) -> None:
    # The core's own check: both tools refuse the same values.
    _core.registration.check_options(**asdict(self))


def _to_kwargs(self) -> dict[str, Any]:
    return asdict(self)


# Every knob of the registration, declared once in the C++ core with its default and
# help (``_core.registration.option_table``); the command lines of both tools walk the
# same table. An enumerated knob has its choices in ``metadata["choices"]``.
RegistrationOptions = options_class(
    "RegistrationOptions", _core.registration.option_table(),
    "Knobs of the registration; the defaults are those of the paper where it gives one.", __name__,
    methods={"__post_init__": _check_options, "to_kwargs": _to_kwargs})


@dataclass
class Step:
    """One step of the registration, as the driver yields it."""

    name: str  # initialize, register, adjust, refine, done
    camera: str | None = None
    # The core's result of the step: InitialPairResult, RegisterResult, AdjustResult or
    # RefineResult (_core.registration); None for done.
    result: Any = None
    candidate: Any = None  # initialize: the PairCandidate; register: the NextCameraCandidate
    adjust: Any = None  # register: the bundle adjustment that followed (AdjustResult)
    new_points: int = 0  # register: points it added
    outliers_changed: int = 0  # register: observations whose inlier status changed
    reason: str = ""  # done: why nothing was registered, if so




class RegistrationDriver:
    """Registers the cameras of ``tracks`` step by step (see the module docstring).

    Cameras without intrinsics are reported as failed and left out.
    """

    def __init__(
        self,
        tracks: Tracks,
        intrinsics: Mapping[str, Intrinsics],
        options: RegistrationOptions | None = None,
        left_out: Mapping[str, str] | None = None,
        projector: ProjectedMarkers | None = None,
        lens_covariance: LensCovariance | None = None,
    ) -> None:
        self.options = options or RegistrationOptions()
        # Cameras that failed before registration (e.g. their video), with the reason.
        self.failed: dict[str, str] = {name: reason for name, reason in (left_out or {}).items()
                                       if name in tracks.camera_names}
        for name in tracks.camera_names:
            if name not in intrinsics and name not in self.failed:
                self.failed[name] = "no intrinsics for this camera"
                logger.warning("camera %s: no intrinsics, left out", name)
        missing = list(self.failed)
        self.all_cameras = tuple(tracks.camera_names)
        self.tracks = tracks.drop_cameras(missing) if missing else tracks
        self.initial_pair: tuple[str, str] | None = None
        self._final: Calibration | None = None  # the calibration once refined
        if not self.tracks.camera_names:
            self.reconstruction = None  # every camera failed before registration
            return
        self.intrinsics = {name: intrinsics[name] for name in self.tracks.camera_names}
        K = np.array([self.intrinsics[name].K for name in self.tracks.camera_names]).reshape(-1, 3, 3)
        sizes = np.array([self.intrinsics[name].image_size() for name in self.tracks.camera_names]).reshape(-1, 2)
        camera_index, point_index, xy = self.tracks.bundle_arrays()
        self.reconstruction = _core.registration.Reconstruction(
            K, sizes, self.tracks.num_points, camera_index, point_index, xy, **self.options.to_kwargs()
        )
        if projector is not None:
            ids = np.asarray(self.tracks.point_ids, dtype=np.int64)
            self.reconstruction.set_projector(projector.pixels(ids), *projector.projector, projector.largest_sides(ids))
        if lens_covariance is not None:
            self._set_lenses(lens_covariance)

    def _set_lenses(self, lens_covariance: LensCovariance) -> None:
        """The refined lenses and how they err: the poses' covariance takes them in."""
        cameras = [name for name in lens_covariance.cameras if name in self.intrinsics]
        for name in cameras:
            lens = self.intrinsics[name]
            self.reconstruction.set_lens_uncertainty(self.tracks.camera_names.index(name), lens.K,
                                                     np.asarray(lens.dist, dtype=float).ravel(),
                                                     lens_covariance.of(name))
        self.reconstruction.set_lens_cross_covariances([self.tracks.camera_names.index(name) for name in cameras],
                                                       lens_covariance.among(cameras))

    def name(self, camera: int) -> str:
        return self.tracks.camera_names[camera]

    def steps(self) -> Iterator[Step]:
        """The steps of the C++ ``run()``, in its order, yielding after each one."""
        rec = self.reconstruction
        if rec is None:
            yield Step("done", reason="no camera to register")
            return
        for pair in rec.rank_initial_pairs():
            info = rec.initialize(pair.camera1, pair.camera2)
            names = (self.name(pair.camera1), self.name(pair.camera2))
            if info.success:
                self.initial_pair = names
                logger.info("initial pair %s-%s: %d homography inliers, %d points", *names,
                            info.homography_inliers, info.points)
                yield Step("initialize", f"{names[0]}-{names[1]}", info, candidate=pair)
                break
            logger.info("initial pair %s-%s rejected: %s", *names, info.reason)
        if self.initial_pair is None:
            rec.fail_unregistered()
            yield Step("done", reason="no camera pair could be initialised")
            return
        yield Step("adjust", None, rec.adjust(False))
        while (next_camera := rec.choose_next_camera()).camera >= 0:
            camera = next_camera.camera
            info = rec.register_camera(camera)
            if not info.success:
                logger.warning("camera %s failed: %s", self.name(camera), info.reason)
                yield Step("register", self.name(camera), info, candidate=next_camera)
                continue
            new_points = rec.add_points(camera)
            adjusted = rec.adjust(False)
            outliers_changed = rec.filter_outliers()
            logger.info("camera %s registered: %d of %d correspondences, %.3f px, %d new points",
                        self.name(camera), info.inliers, info.correspondences, info.mean_error_px, new_points)
            yield Step("register", self.name(camera), info, candidate=next_camera, adjust=adjusted,
                       new_points=new_points, outliers_changed=outliers_changed)
        rec.fail_unregistered()
        refined = rec.refine()
        if refined.relief.tested:
            logger.info("%s", refined.relief.message)
        logger.info("refined: %d rounds, %d observations left out as outliers, cost %.6g",
                    refined.rounds, refined.removed, refined.last.final_cost)
        self._final = self.result()
        _warn_weak_cameras(self._final, self.options.weak_rotation_sigma_deg)
        yield Step("refine", None, refined)
        yield Step("done")

    def run(self, callback: Callable[[Step], bool | None] | None = None) -> Calibration:
        """All steps; ``callback(step)`` returning False stops after that step."""
        for step in self.steps():
            if callback is not None and callback(step) is False:
                return self.result()
        # Nothing changes after the refinement: its calibration is the result.
        return self._final if self._final is not None else self.result()

    def result(self) -> Calibration:
        """The calibration in the floor frame, from the current state."""
        if self.reconstruction is None:
            return Calibration.nothing_registered(self.failed, self.options.model)
        return self.reconstruction.calibration(self.tracks.camera_names, self.tracks.point_ids,
                                               list(self.failed.items()), self.options.model)


def _warn_weak_cameras(calibration: Calibration, limit_deg: float) -> None:
    for name in calibration.registered:
        metrics = calibration.metrics[name]
        if metrics.weak:
            # The centre's sigma waits for the final calibration, in the results' unit.
            logger.warning("camera %s is weakly determined: rotation known to %.3f deg (1 sigma, limit %g); "
                           "more points in its view help (calibproj generate --densify RESULTS "
                           "plans a short extra projection for it)", name, metrics.rotation_sigma_deg, limit_deg)


def register(
    tracks: Tracks,
    intrinsics: Mapping[str, Intrinsics],
    options: RegistrationOptions | None = None,
    callback: Callable[[Step], bool | None] | None = None,
    left_out: Mapping[str, str] | None = None,
    projector: ProjectedMarkers | None = None,
    lens_covariance: LensCovariance | None = None,
) -> Calibration:
    """Register every camera of ``tracks`` and return the ``Calibration`` (floor frame).

    ``left_out`` names cameras that failed before registration, with the reason.
    ``projector``: where the projector drew every MSM (from the sequence); with it the
    coplanar model ties each centre to the floor through the projector's maps.
    ``lens_covariance``: how the lenses refined by the self-calibration err (their joint
    covariance); the poses' covariance then takes it in.
    """
    return RegistrationDriver(tracks, intrinsics, options, left_out, projector, lens_covariance).run(callback)
