"""The Python driver of the incremental registration (paper section 2.2).

Every algorithmic step is one C++ method of ``calibproj._core.registration.Reconstruction``;
this driver owns the tracks, calls those steps in the order of the C++ ``run()``, logs
each camera as it is added, and yields after every step so that a caller can watch,
hook in, or stop::

    driver = RegistrationDriver(tracks, intrinsics)
    for step in driver.steps():
        print(step.name, step.info)
    calibration = driver.result()

``calibrate(tracks, intrinsics)`` does all of it and returns a ``Calibration``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Mapping
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from calibproj import _core
from calibproj.calibration import MODELS, Calibration
from calibproj.io.intrinsics import Intrinsics
from calibproj.tracks import Tracks

if TYPE_CHECKING:
    from calibproj.scale import ProjectedMarkers

logger = logging.getLogger(__name__)

LOSSES = ("none", "huber", "cauchy")


@dataclass
class RegistrationOptions:
    """Knobs of the registration; the defaults are those of the paper where it gives one.

    Attributes:
        model: ``"coplanar"`` (points on one refined plane, as in the paper's results) or
            ``"free"`` (3D points).
        homography_threshold_px: RANSAC threshold of the initial pair's homography, in
            each camera's own pixels (3 px in the paper).
        pnp_threshold_px: RANSAC threshold of PnP for each new camera, in its pixels.
        ransac_max_iterations: upper bound of RANSAC iterations.
        ransac_confidence: RANSAC stops once a better model is this unlikely.
        seed: RANSAC random seed (results are reproducible for a given seed).
        min_pair_points: common points needed for the initial pair and the third camera.
        min_pnp_points: correspondences needed to register a camera.
        min_triangulation_angle_deg: FREE model: parallax needed to triangulate a point.
        min_pair_parallax_deg: median parallax the initial pair's points need (two cameras
            at nearly the same place determine neither the plane nor the points).
        outlier_threshold_px: smallest reprojection error at which an observation is
            removed (1 px in the paper).
        outlier_sigma_factor: the threshold is ``max(outlier_threshold_px, factor * sigma)``
            with sigma a robust estimate of each camera's noise; 0 keeps the fixed threshold.
        max_refine_rounds: bundle adjustment and outlier removal rounds at the end.
        view_score_levels: levels of the visibility pyramid of the view score.
        loss: robust loss of the bundle adjustment (``none``, ``huber``, ``cauchy``).
        loss_scale_px: scale of the robust loss in pixels.
        num_threads: threads of the bundle adjustment.
        intermediate_ba_iterations: iterations of the bundle adjustment after each camera.
        final_ba_iterations: iterations of the final bundle adjustments.
        weak_rotation_sigma_deg: a camera whose rotation is known worse than this (1
            sigma along the worst axis, from the final bundle adjustment's covariance)
            is reported as weak: few points, a small or near-affine view.
        max_planes: coplanar model: points off the floor (a table, a cart left in the
            projection) are triangulated, and up to this many more planes are found
            among them (RANSAC) and refined with the rest (0: none).
        min_plane_points: points a plane needs to be found.
        plane_distance: a point belongs to a plane within this distance, in units of
            the first camera's height above the floor.
        use_projector: coplanar model with the sequence known: tie every centre's
            floor (or table) position to its projector pixel through each surface's
            projector map (a homography and the projector lens's radial distortion,
            refined with the rest), so that centres one camera alone sees count too,
            and a camera can be registered on centres no other camera placed.
        min_projector_pnp_points: centres a camera needs to be registered once the
            projector places them.
        estimate_noise: weight each camera by the noise its own centres show and the
            projector by its maps' (variance components), and scale the pose
            covariance with them; off: one noise for every camera.
        projector_sigma_px: the projector maps' noise (projector pixels) until it is
            estimated, or for good with estimate_noise off.
        error_correlation: the correlation of one camera's centre errors (and of the
            projector's): a share of each error that its centres have in common (the
            lens model, blur, a floor's texture) is not averaged away by their number, so
            the pose covariance counts a camera's N centres as N / (1 + (N - 1) *
            error_correlation) independent ones. The poses do not depend on it.
        floor_relief: coplanar: the expected root mean square height of the floor's
            unevenness, as a share of the extent of the centres on it (0.001: 3 mm
            over a 3 m projection). The floor's centres may leave its plane by a smooth
            relief with that prior, which cameras seeing them from several directions
            measure; a camera zoomed onto a patch of floor is then not handed the
            patch's slope as its own tilt. 0: an exactly flat floor.
    """

    model: str = "coplanar"
    homography_threshold_px: float = 3.0
    pnp_threshold_px: float = 3.0
    ransac_max_iterations: int = 2000
    ransac_confidence: float = 0.9999
    seed: int = 0
    min_pair_points: int = 15
    min_pnp_points: int = 6
    min_triangulation_angle_deg: float = 1.0
    min_pair_parallax_deg: float = 2.0
    outlier_threshold_px: float = 1.0
    outlier_sigma_factor: float = 3.0
    max_refine_rounds: int = 10
    view_score_levels: int = 6
    loss: str = "none"
    loss_scale_px: float = 1.0
    num_threads: int = 1
    intermediate_ba_iterations: int = 25
    final_ba_iterations: int = 100
    weak_rotation_sigma_deg: float = 0.05
    max_planes: int = 3
    min_plane_points: int = 30
    plane_distance: float = 0.004
    use_projector: bool = True
    min_projector_pnp_points: int = 4
    estimate_noise: bool = True
    projector_sigma_px: float = 0.1
    error_correlation: float = 0.005
    floor_relief: float = 0.001

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise ValueError(f"model must be one of {MODELS}, got {self.model!r}")
        if self.loss not in LOSSES:
            raise ValueError(f"loss must be one of {LOSSES}, got {self.loss!r}")

    def to_kwargs(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class Step:
    """One step of the registration, as the driver yields it."""

    name: str  # initialize, register, adjust, refine, done
    camera: str | None = None
    info: dict[str, Any] = field(default_factory=dict)


def image_size(intrinsics: Intrinsics) -> tuple[float, float]:
    """The camera's image size, or twice its principal point when the file gives none."""
    if intrinsics.resolution is not None:
        return float(intrinsics.resolution[0]), float(intrinsics.resolution[1])
    return 2.0 * float(intrinsics.K[0, 2]) + 1.0, 2.0 * float(intrinsics.K[1, 2]) + 1.0


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
        if not self.tracks.camera_names:
            self.reconstruction = None  # every camera failed before registration
            return
        self.intrinsics = {name: intrinsics[name] for name in self.tracks.camera_names}
        K = np.array([self.intrinsics[name].K for name in self.tracks.camera_names]).reshape(-1, 3, 3)
        sizes = np.array([image_size(self.intrinsics[name]) for name in self.tracks.camera_names]).reshape(-1, 2)
        camera_index, point_index, xy = self.tracks.bundle_arrays()
        self.reconstruction = _core.registration.Reconstruction(
            K, sizes, self.tracks.num_points, camera_index, point_index, xy, **self.options.to_kwargs()
        )
        if projector is not None:
            pixels = _core.formats.projector_pixels(projector, np.asarray(self.tracks.point_ids, dtype=np.int64))
            self.reconstruction.set_projector(pixels, *projector.projector)

    def name(self, camera: int) -> str:
        return self.tracks.camera_names[camera]

    def steps(self) -> Iterator[Step]:
        """The steps of the C++ ``run()``, in its order, yielding after each one."""
        rec = self.reconstruction
        if rec is None:
            yield Step("done", None, {"reason": "no camera to register"})
            return
        for pair in rec.rank_initial_pairs():
            info = rec.initialize(pair["camera1"], pair["camera2"])
            names = (self.name(pair["camera1"]), self.name(pair["camera2"]))
            if info["success"]:
                self.initial_pair = names
                logger.info("initial pair %s-%s: %d homography inliers, %d points", *names,
                            info["homography_inliers"], info["points"])
                yield Step("initialize", f"{names[0]}-{names[1]}", {**pair, **info})
                break
            logger.info("initial pair %s-%s rejected: %s", *names, info["reason"])
        if self.initial_pair is None:
            rec.fail_unregistered()
            yield Step("done", None, {"reason": "no camera pair could be initialised"})
            return
        yield Step("adjust", None, rec.adjust(False))
        while (next_camera := rec.choose_next_camera())["camera"] >= 0:
            camera = next_camera["camera"]
            info = rec.register_camera(camera)
            if not info["success"]:
                logger.warning("camera %s failed: %s", self.name(camera), info["reason"])
                yield Step("register", self.name(camera), {**next_camera, **info})
                continue
            info["new_points"] = rec.add_points(camera)
            adjusted = rec.adjust(False)
            info["outliers_changed"] = rec.filter_outliers()
            logger.info("camera %s registered: %d of %d correspondences, %.3f px, %d new points",
                        self.name(camera), info["inliers"], info["correspondences"], info["mean_error_px"],
                        info["new_points"])
            yield Step("register", self.name(camera), {**next_camera, **info, "adjust": adjusted})
        rec.fail_unregistered()
        refined = rec.refine()
        logger.info("refined: %d rounds, %d observations left out as outliers, cost %.6g",
                    refined["rounds"], refined["removed"], refined["last"]["final_cost"])
        self._warn_weak_cameras()
        yield Step("refine", None, refined)
        yield Step("done", None, {})

    def _warn_weak_cameras(self) -> None:
        summary = self.reconstruction.summarize()
        for c, name in enumerate(self.tracks.camera_names):
            if summary["registered"][c] and summary["weak"][c]:
                logger.warning("camera %s is weakly determined: rotation known to %.3f deg (1 sigma, limit %g), "
                               "centre to %.3g units; more points in its view help (calibproj generate --densify RESULTS "
                               "plans a short extra projection for it)",
                               name, summary["rotation_sigma_deg"][c], self.options.weak_rotation_sigma_deg,
                               summary["centre_sigma"][c])

    def run(self, callback: Callable[[Step], bool | None] | None = None) -> Calibration:
        """All steps; ``callback(step)`` returning False stops after that step."""
        for step in self.steps():
            if callback is not None and callback(step) is False:
                break
        return self.result()

    def result(self) -> Calibration:
        """The calibration in the floor frame, from the current state."""
        if self.reconstruction is None:
            return Calibration.nothing_registered(self.failed, self.options.model)
        return Calibration.from_summary(
            self.reconstruction.summarize(),
            self.tracks.camera_names,
            self.tracks.point_ids,
            self.failed,
            self.options.model,
        )


def calibrate(
    tracks: Tracks,
    intrinsics: Mapping[str, Intrinsics],
    options: RegistrationOptions | None = None,
    callback: Callable[[Step], bool | None] | None = None,
    left_out: Mapping[str, str] | None = None,
    projector: ProjectedMarkers | None = None,
) -> Calibration:
    """Register every camera of ``tracks`` and return the ``Calibration`` (floor frame).

    ``left_out`` names cameras that failed before registration, with the reason.
    ``projector``: where the projector drew every MSM (from the sequence); with it the
    coplanar model ties each centre to the floor through the projector's maps.
    """
    return RegistrationDriver(tracks, intrinsics, options, left_out, projector).run(callback)
