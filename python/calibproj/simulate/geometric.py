"""Geometric simulation: where the cameras of a scene see the projected MSM centres.

No images are rendered. The MSM centres of a layout (projector pixels) are cast
through the projector onto the floor (z = 0, or its relief); a camera observes a centre when the
marker, at one of its scales at least, would be decodable: its square, cast
projector -> floor -> camera (with lens distortion), lies wholly inside the image
and its shortest side is at least ``min_marker_px`` long. An observation is the
undistorted pinhole projection of the centre plus Gaussian noise; a chosen share
of them can be replaced by gross outliers drawn uniformly over the image.

An independent evaluation set, like the paper's ChArUco recordings, is drawn in the
working volume above the floor (partly uniform, partly inside each camera's view so
that every camera, the zoomed one included, gets some), observed by every camera
that has the point in front of it and inside its image, and kept when at least two
cameras see it.

Random draws come from independent streams of one seed, so changing, say, the
outlier share leaves the noise of the other observations unchanged.
"""

from __future__ import annotations

import logging
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from calibproj.sequence.layout import MsmLayout
from calibproj.sequence.sequence import Sequence
from calibproj.formats.intrinsics import Intrinsics, write_intrinsics_dir
from calibproj.simulate import boxes
from calibproj.simulate.scene import Camera, Scene, load_scene, save_scene
from calibproj.simulate.truth import truth_document, write_truth
from calibproj.formats.tracks import Tracks

logger = logging.getLogger(__name__)

DEFAULT_NOISE_PX = 0.5
DEFAULT_MIN_MARKER_PX = 15.0
DEFAULT_EVAL_POINTS = 1000
DEFAULT_EVAL_POINTS_PER_CAMERA = 100
DEFAULT_EVAL_HEIGHT_M = 2.0
DEFAULT_MIN_DEPTH_M = 0.1
MIN_EVAL_VIEWS = 2

# Corners of a marker square in the order they go round it (for its side lengths).
SQUARE_CORNERS = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])


@dataclass(frozen=True, eq=False)
class Projection:
    """World points seen by one camera.

    Attributes:
        distorted: image pixels (with lens distortion), NaN where not ``visible``.
        undistorted: pinhole pixels (same K), NaN where not ``visible``.
        visible: in front of the camera, where the lens model is one-to-one, and
            inside the image.
    """

    distorted: np.ndarray
    undistorted: np.ndarray
    visible: np.ndarray


def project_points(camera: Camera, points: np.ndarray, min_depth_m: float = DEFAULT_MIN_DEPTH_M) -> Projection:
    """Project world points ``(N, 3)`` into a camera of a scene."""
    intrinsics = camera.intrinsics
    in_camera = np.asarray(points, dtype=float).reshape(-1, 3) @ camera.R.T + camera.t
    depth = in_camera[:, 2]
    in_front = depth > min_depth_m
    normalized = in_camera[:, :2] / np.where(in_front, depth, 1.0)[:, None]
    modelled = in_front & (np.linalg.norm(normalized, axis=1) <= intrinsics.max_monotonic_radius())
    normalized[~modelled] = 0.0  # keeps the lens model finite; those rows are masked below
    distorted = intrinsics.project_normalized(normalized)
    undistorted = normalized @ camera.K[:2, :2].T + camera.K[:2, 2]
    visible = modelled & intrinsics.contains(distorted)
    distorted[~modelled] = np.nan
    undistorted[~modelled] = np.nan
    return Projection(distorted, undistorted, visible)


def msm_floor_points(scene: Scene, layout: MsmLayout) -> np.ndarray:
    """Where all MSM centres land, shape ``(arrays * markers_per_array, 3)``; row = point
    id: on the floor, or on a box standing in the projection (``msm_surfaces``)."""
    return projected_points(scene, layout.centres().reshape(-1, 2))[0]


def msm_surfaces(scene: Scene, layout: MsmLayout) -> np.ndarray:
    """The surface (``calibproj.simulate.boxes``: 0 the floor) each MSM centre lands on."""
    return projected_points(scene, layout.centres().reshape(-1, 2))[1]


def marker_corners_on_floor(scene: Scene, layout: MsmLayout) -> np.ndarray:
    """Where the square corners of every MSM at every scale land, ``(P, scales, 4, 3)``."""
    return _marker_corners(scene, layout)[0]


def _marker_corners(scene: Scene, layout: MsmLayout) -> tuple[np.ndarray, np.ndarray]:
    """The corners' points ``(P, scales, 4, 3)`` and surfaces ``(P, scales, 4)``."""
    centres = layout.centres().reshape(-1, 2)
    half_sides = 0.5 * layout.marker_px * np.asarray(layout.scales)
    corners = centres[:, None, None, :] + half_sides[None, :, None, None] * SQUARE_CORNERS[None, None]
    points, surfaces = projected_points(scene, corners.reshape(-1, 2))
    return points.reshape(*corners.shape[:3], 3), surfaces.reshape(corners.shape[:3])


def projected_points(scene: Scene, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where projector pixels' rays land: ``(points (N, 3), surfaces (N,))``, the
    floor unless a box stands in the way (NaN and -1 for rays that land nowhere)."""
    if not scene.boxes:
        points = scene.projector.pixels_to_floor(pixels, scene.floor)
        return points, np.where(np.isfinite(points[:, 0]), boxes.FLOOR, -1)
    pixels = scene.projector.ideal_pixels(pixels)
    rays = np.linalg.solve(scene.projector.K, np.column_stack([pixels, np.ones(len(pixels))]).T)
    return boxes.first_hits(scene.projector.center, (scene.projector.R.T @ rays).T, scene.boxes, scene.floor)


def decodable_msms(
    camera: Camera,
    centres: np.ndarray,
    corners: np.ndarray,
    min_marker_px: float = DEFAULT_MIN_MARKER_PX,
    min_depth_m: float = DEFAULT_MIN_DEPTH_M,
    scene_boxes: tuple = (),
    surfaces: tuple[np.ndarray, np.ndarray] | None = None,
    shown: np.ndarray | None = None,
) -> np.ndarray:
    """Per MSM, whether the camera could decode it at one of its scales at least.

    Args:
        camera: the observing camera.
        centres: where the MSM centres land, ``(P, 3)`` (``msm_floor_points``).
        corners: where their square corners land, ``(P, scales, 4, 3)``
            (``marker_corners_on_floor``).
        min_marker_px: shortest side, in image pixels, of a decodable marker.
        min_depth_m: nearest distance in front of the camera at which it sees a point.
        scene_boxes: boxes that may hide corners and centres from the camera.
        surfaces: the surfaces of the centres ``(P,)`` and corners ``(P, scales, 4)``:
            a marker whose corners do not all lie on its centre's surface is folded
            over an edge and not decoded at that scale.
        shown: which scales each MSM is shown at ``(P, scales)``; None: all of them.
    """
    seen = project_points(camera, corners.reshape(-1, 3), min_depth_m)
    image = seen.distorted.reshape(*corners.shape[:3], 2)
    sides = np.linalg.norm(image - np.roll(image, -1, axis=2), axis=-1).min(axis=2)
    visible = seen.visible
    centre_visible = project_points(camera, centres, min_depth_m).visible
    if scene_boxes:
        visible = visible & ~boxes.hidden(camera.center, corners.reshape(-1, 3), scene_boxes)
        centre_visible = centre_visible & ~boxes.hidden(camera.center, centres, scene_boxes)
    inside = visible.reshape(corners.shape[:3]).all(axis=2)
    large_enough = inside & (np.nan_to_num(sides, nan=0.0) >= min_marker_px)
    if surfaces is not None:
        centre_surface, corner_surfaces = surfaces
        large_enough &= np.all(corner_surfaces == centre_surface[:, None, None], axis=2)
    if shown is not None:
        large_enough &= shown
    return large_enough.any(axis=1) & centre_visible


def sample_eval_points(
    scene: Scene,
    rng: np.random.Generator,
    count: int = DEFAULT_EVAL_POINTS,
    per_camera: int = DEFAULT_EVAL_POINTS_PER_CAMERA,
    height_m: float = DEFAULT_EVAL_HEIGHT_M,
    min_depth_m: float = DEFAULT_MIN_DEPTH_M,
) -> np.ndarray:
    """Points in the working volume (floor rectangle x [0, height_m]): ``count`` uniform, plus
    up to ``per_camera`` inside each camera's view (drawn along rays of random pixels)."""
    width, depth = scene.floor.size_m
    lower = np.array([-width / 2.0, -depth / 2.0, 0.0])
    upper = np.array([width / 2.0, depth / 2.0, height_m])
    parts = [rng.uniform(lower, upper, size=(count, 3))]
    for camera in scene.cameras:
        parts.append(_sample_in_view(camera, rng, per_camera, lower, upper, min_depth_m))
    return np.concatenate(parts)


def _sample_in_view(camera: Camera, rng: np.random.Generator, count: int, lower: np.ndarray,
                    upper: np.ndarray, min_depth_m: float) -> np.ndarray:
    width, height = camera.resolution
    pixels = rng.uniform([-0.5, -0.5], [width - 0.5, height - 0.5], size=(count, 2))
    intrinsics = camera.intrinsics
    normalized = intrinsics.normalize(intrinsics.undistort_points(pixels))
    rays = np.column_stack([normalized, np.ones(count)]) @ camera.R  # world directions, unit depth
    with np.errstate(divide="ignore", invalid="ignore"):
        to_lower = (lower - camera.center) / rays
        to_upper = (upper - camera.center) / rays
    near = np.fmax(np.nanmax(np.fmin(to_lower, to_upper), axis=1), min_depth_m)
    far = np.nanmin(np.fmax(to_lower, to_upper), axis=1)
    crosses = far > near
    depth = rng.uniform(np.where(crosses, near, 0.0), np.where(crosses, far, 0.0))
    return (camera.center + depth[:, None] * rays)[crosses]


@dataclass(frozen=True, eq=False)
class GeometricSimulation:
    """Everything a tracks-only simulation produces.

    Attributes:
        scene: the realised scene (random parts drawn).
        layout: the MSM layout projected.
        tracks: noisy undistorted observations of the MSM centres (point id = MSM id).
        eval_tracks: noisy undistorted observations of the evaluation points.
        msm_points: floor position of every MSM centre, row = point id, shape ``(P, 3)``.
        eval_points: evaluation points, row = point id of ``eval_tracks``, shape ``(E, 3)``.
        outliers: camera -> point ids whose observation is a gross outlier.
        settings: the knobs used (noise, seed, ...), written into ``truth.json``.
    """

    scene: Scene
    layout: MsmLayout
    tracks: Tracks
    eval_tracks: Tracks
    msm_points: np.ndarray
    eval_points: np.ndarray
    outliers: dict[str, np.ndarray]
    settings: dict

    @property
    def intrinsics(self) -> dict[str, Intrinsics]:
        return {camera.name: camera.intrinsics for camera in self.scene.cameras}

    def truth(self) -> dict:
        """Body of ``truth.json``."""
        extra = {
            "simulation": {"kind": "geometric", **self.settings, "layout": _layout_record(self.layout)},
            "outliers": {name: ids.tolist() for name, ids in self.outliers.items()},
        }
        msm_ids = np.arange(len(self.msm_points))
        eval_ids = np.arange(len(self.eval_points))
        document = truth_document(
            self.scene, (msm_ids, self.msm_points), self.layout.markers_per_array,
            (eval_ids, self.eval_points), extra,
        )
        if self.scene.boxes:  # which surface each MSM centre lies on (numbers of "surfaces")
            document["points"]["surface"] = msm_surfaces(self.scene, self.layout).tolist()
        return document

    def write(self, out: str | os.PathLike) -> None:
        """Write tracks.json, eval_tracks.json, intrinsics/<camera>.json, truth.json and scene.json."""
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        self.tracks.write(out / "tracks.json")
        self.eval_tracks.write(out / "eval_tracks.json")
        write_intrinsics_dir(out / "intrinsics", self.intrinsics)
        save_scene(out / "scene.json", self.scene)
        write_truth(out / "truth.json", self.truth())


def simulate_tracks(
    scene: Scene | str | os.PathLike,
    out: str | os.PathLike | None = None,
    *,
    noise_px: float = DEFAULT_NOISE_PX,
    seed: int = 0,
    outlier_fraction: float = 0.0,
    min_marker_px: float = DEFAULT_MIN_MARKER_PX,
    layout: MsmLayout | Sequence | None = None,
    eval_points: int = DEFAULT_EVAL_POINTS,
    eval_points_per_camera: int = DEFAULT_EVAL_POINTS_PER_CAMERA,
    eval_height_m: float = DEFAULT_EVAL_HEIGHT_M,
    min_depth_m: float = DEFAULT_MIN_DEPTH_M,
) -> GeometricSimulation:
    """Simulate MSM tracks and an evaluation set for a scene, with ground truth.

    Args:
        scene: a ``Scene``, a preset name or a scene file (presets draw their random
            parts from ``seed``).
        out: when given, the directory to write the files into (see ``GeometricSimulation.write``).
        noise_px: standard deviation of the Gaussian noise on every coordinate, pixels.
        seed: seed of every random draw.
        outlier_fraction: share of MSM observations replaced by a uniform draw over the image.
        min_marker_px: shortest marker side, in image pixels, that a camera still decodes.
        layout: MSM layout; default ``MsmLayout`` at the projector's resolution. A
            ``Sequence`` gives its own centres and, per marker, the scales its patterns
            show it at: an array it never shows is not observed (a densified sequence
            shows only its new ones, each at the scales of the camera it is planned for).
        eval_points: evaluation points drawn uniformly in the working volume.
        eval_points_per_camera: extra evaluation points drawn inside each camera's view.
        eval_height_m: height of the working volume above the floor.
        min_depth_m: nearest distance in front of a camera at which it sees a point.
    """
    _check_settings(noise_px, outlier_fraction, min_marker_px, eval_points, eval_points_per_camera, eval_height_m)
    if not isinstance(scene, Scene):
        scene = load_scene(scene, seed=seed)
    if isinstance(layout, Sequence):
        layout = sequence_layout(layout)
    layout = layout or MsmLayout(projector=scene.projector.resolution)
    noise_rng, outlier_rng, eval_rng, eval_noise_rng = (
        np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4)
    )
    msm_points = msm_floor_points(scene, layout)
    tracks, outliers = _msm_tracks(scene, layout, msm_points, noise_rng, outlier_rng, noise_px,
                                   outlier_fraction, min_marker_px, min_depth_m)
    eval_xyz, eval_tracks = evaluation_tracks(scene, eval_rng, eval_noise_rng, noise_px, eval_points,
                                              eval_points_per_camera, eval_height_m, min_depth_m)
    settings = {"noise_px": noise_px, "seed": seed, "outlier_fraction": outlier_fraction,
                "min_marker_px": min_marker_px, "eval_height_m": eval_height_m, "min_depth_m": min_depth_m}
    simulation = GeometricSimulation(scene, layout, tracks, eval_tracks, msm_points, eval_xyz, outliers, settings)
    logger.info("simulated %d MSM observations of %d points, %d evaluation observations of %d points",
                len(tracks), tracks.num_points, len(eval_tracks), eval_tracks.num_points)
    if out is not None:
        simulation.write(out)
    return simulation


@dataclass(frozen=True, eq=False)
class _PlacedLayout(MsmLayout):
    """A layout whose centres are given (as a sequence file holds them)."""

    placed: tuple = ()  # (arrays, markers, 2) as nested tuples: written into truth.json as they are
    shown: tuple = ()  # (arrays, markers, scales) booleans: which scales each marker is shown at

    def centres(self) -> np.ndarray:
        return np.asarray(self.placed, dtype=np.float64)


def _layout_record(layout: MsmLayout) -> dict:
    """The layout as truth.json keeps it: its centres, without the per-marker scale mask."""
    record = asdict(layout)
    record.pop("shown", None)
    return record


def shown_scales(layout: MsmLayout) -> np.ndarray:
    """Per MSM and scale, whether a pattern shows it ``(P, scales)``: a sequence shows
    each array at its own scales (a densified one at the scales of the camera it is
    planned for) and leaves out markers that would overlap or leave the image."""
    if isinstance(layout, _PlacedLayout) and layout.shown:
        return np.asarray(layout.shown, dtype=bool).reshape(-1, len(layout.scales))
    return np.ones((layout.arrays * layout.markers_per_array, len(layout.scales)), dtype=bool)


def sequence_layout(sequence: Sequence) -> MsmLayout:
    """The layout of ``sequence`` as the simulation needs it: its centres, wherever they
    are (a densified sequence places its own), and only the scales its patterns show."""
    layout = sequence.layout
    scales = sorted({pattern.scale for pattern in sequence.patterns})
    shown = np.zeros((layout.arrays, layout.markers_per_array, len(scales)), dtype=bool)
    for pattern in sequence.patterns:
        column = scales.index(pattern.scale)
        shown[pattern.array, :, column] = True
        shown[pattern.array, list(pattern.omitted), column] = False
    return _PlacedLayout(projector=layout.projector, grid=layout.grid, arrays=layout.arrays, scales=tuple(scales),
                         marker_px=layout.marker_px, margin_px=layout.margin, snap_to_pixels=layout.snap_to_pixels,
                         placed=tuple(tuple(tuple(centre) for centre in array) for array in sequence.centres.tolist()),
                         shown=tuple(shown.ravel().tolist()))


def _check_settings(noise_px: float, outlier_fraction: float, min_marker_px: float, eval_points: int,
                    eval_points_per_camera: int, eval_height_m: float) -> None:
    if not noise_px >= 0:
        raise ValueError(f"noise must be >= 0 px, got {noise_px}")
    if not 0.0 <= outlier_fraction <= 1.0:
        raise ValueError(f"outlier fraction must be in [0, 1], got {outlier_fraction}")
    if not min_marker_px > 0:
        raise ValueError(f"minimum marker size must be positive, got {min_marker_px} px")
    if eval_points < 0 or eval_points_per_camera < 0:
        raise ValueError("numbers of evaluation points must be >= 0")
    if not eval_height_m > 0:
        raise ValueError(f"working volume height must be positive, got {eval_height_m} m")


def _msm_tracks(scene: Scene, layout: MsmLayout, msm_points: np.ndarray, noise_rng: np.random.Generator,
                outlier_rng: np.random.Generator, noise_px: float, outlier_fraction: float,
                min_marker_px: float, min_depth_m: float) -> tuple[Tracks, dict[str, np.ndarray]]:
    corners, corner_surfaces = _marker_corners(scene, layout)
    surfaces = (msm_surfaces(scene, layout), corner_surfaces)
    shown = shown_scales(layout)
    cameras, ids, xy = [], [], []
    for index, camera in enumerate(scene.cameras):
        seen = decodable_msms(camera, msm_points, corners, min_marker_px, min_depth_m, scene.boxes, surfaces, shown)
        point_ids = np.flatnonzero(seen)
        pixels = project_points(camera, msm_points[point_ids], min_depth_m).undistorted
        cameras.append(np.full(len(point_ids), index))
        ids.append(point_ids)
        xy.append(pixels + noise_rng.normal(0.0, noise_px, size=pixels.shape))
        logger.debug("camera %s decodes %d MSMs", camera.name, len(point_ids))
    camera_index, point_ids, pixels = np.concatenate(cameras), np.concatenate(ids), np.concatenate(xy)
    outlier_rows = _replace_by_outliers(scene, outlier_rng, camera_index, pixels, outlier_fraction)
    outliers = {
        camera.name: np.sort(point_ids[outlier_rows[camera_index[outlier_rows] == index]])
        for index, camera in enumerate(scene.cameras)
    }
    tracks = Tracks.from_observations(scene.camera_names, camera_index, point_ids, pixels, layout.markers_per_array)
    return tracks, outliers


def _replace_by_outliers(scene: Scene, rng: np.random.Generator, camera_index: np.ndarray, pixels: np.ndarray,
                         fraction: float) -> np.ndarray:
    """Overwrite a share of the observations (in place) with undistorted uniform image draws."""
    rows = rng.choice(len(pixels), size=int(round(fraction * len(pixels))), replace=False)
    for index, camera in enumerate(scene.cameras):
        chosen = rows[camera_index[rows] == index]
        width, height = camera.resolution
        drawn = rng.uniform([-0.5, -0.5], [width - 0.5, height - 0.5], size=(len(chosen), 2))
        pixels[chosen] = camera.intrinsics.undistort_points(drawn)
    return rows


def evaluation_tracks(
    scene: Scene,
    point_rng: np.random.Generator,
    noise_rng: np.random.Generator,
    noise_px: float,
    count: int = DEFAULT_EVAL_POINTS,
    per_camera: int = DEFAULT_EVAL_POINTS_PER_CAMERA,
    height_m: float = DEFAULT_EVAL_HEIGHT_M,
    min_depth_m: float = DEFAULT_MIN_DEPTH_M,
) -> tuple[np.ndarray, Tracks]:
    """Evaluation points in the working volume (``sample_eval_points``) seen by two
    cameras at least, and their noisy undistorted observations: ``(points, tracks)``,
    row ``i`` of points being point id ``i`` of the tracks."""
    candidates = sample_eval_points(scene, point_rng, count, per_camera, height_m, min_depth_m)
    return _eval_tracks(scene, candidates, noise_rng, noise_px, min_depth_m)


def _eval_tracks(scene: Scene, candidates: np.ndarray, noise_rng: np.random.Generator, noise_px: float,
                 min_depth_m: float) -> tuple[np.ndarray, Tracks]:
    candidates = candidates[~boxes.inside(candidates, scene.boxes)]
    projections = [project_points(camera, candidates, min_depth_m) for camera in scene.cameras]
    for camera, projection in zip(scene.cameras, projections):
        if scene.boxes:
            np.logical_and(projection.visible, ~boxes.hidden(camera.center, candidates, scene.boxes),
                           out=projection.visible)
    views = np.sum([p.visible for p in projections], axis=0)
    kept = views >= MIN_EVAL_VIEWS
    points = candidates[kept]
    cameras, ids, xy = [], [], []
    for index, projection in enumerate(projections):
        point_ids = np.flatnonzero(projection.visible[kept])
        pixels = projection.undistorted[kept][point_ids]
        cameras.append(np.full(len(point_ids), index))
        ids.append(point_ids)
        xy.append(pixels + noise_rng.normal(0.0, noise_px, size=pixels.shape))
    tracks = Tracks.from_observations(scene.camera_names, np.concatenate(cameras), np.concatenate(ids),
                                      np.concatenate(xy), None)
    return points, tracks
