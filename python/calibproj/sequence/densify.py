"""Targeted densification: a short extra projection where cameras have few points.

A camera zoomed onto the surgical field sees only the few MSM centres of the default
sequence that fall in its small footprint, so its pose is known worse than the others'
(reported weak). Given a first calibration, the camera's footprint is known in the
projector image: its image, cast onto the surface it looks at (the floor or a table top,
whichever holds most of its points) and mapped into projector pixels by the homography
that the calibrated points and their projector pixels give. ``plan_densification``
fills that footprint with extra MSM arrays (the paper's offset arrays, concentrated:
each array a lattice in the footprint, the arrays shifted by fractions of its pitch)
at marker sizes chosen for that camera: large enough to decode there, small enough
that many fit in its view.

The densified sequence keeps every array of the first sequence (same centres, so the
same point ids) and appends the new ones, but shows only the new ones: a recording of
it adds observations with point ids the first calibration does not have, and
``calibproj calibrate ... --merge RESULTS`` calibrates the union. Its length is bounded
(``DensifyOptions.max_seconds``), light codes and reference frames included.
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calibproj.sequence.builder import ShownPattern, overhead_seconds, pattern_budget, reassembled
from calibproj.sequence.layout import MsmLayout, outside_image, snap_centres
from calibproj.sequence.sequence import Sequence

log = logging.getLogger(__name__)

# Fewest calibrated points on a surface for its projector homography (8 unknowns).
MIN_SURFACE_POINTS = 12
# Image samples per side when casting a camera's view onto its surface.
FOOTPRINT_SAMPLES = 9


@dataclass(frozen=True)
class DensifyOptions:
    """How the extra projection is planned.

    Attributes:
        max_seconds: longest extra projection, light codes and reference frames included.
        cameras: the cameras to densify for; None: every registered camera that is
            weak or has fewer than ``min_points`` inliers.
        min_points: inliers below which a camera is densified for (with ``cameras`` None).
        scales_per_msm: marker sizes per MSM (fewer when the camera's range allows fewer).
        min_module_projector_px: smallest module (marker cell) in projector pixels: a
            sharper projector pixel grid cannot be drawn.
        min_side_fraction: smallest marker side in the camera, as a fraction of its
            image's shorter side (large enough to decode and to place the centre well).
        max_side_fraction: largest marker side in the camera, same unit (small enough that
            many fit in its view).
        edge_margin: fraction of the image left out at each border when casting the view
            (centres there are detected on a part of the lens that is known worst).
        min_gap_modules: smallest gap between two markers of one extra array, in modules
            of its largest marker. The markers are sized for the camera densified for, so
            an oblique camera that sees the same place shows them small: with the first
            sequence's half module its blur merges neighbours into each other's edges and
            moves their centres (rendered demo room, a 0.7 px blur: 0.07 px, and a
            systematic 0.08 px stretch across the footprint, at 0.5 modules; 0.012 px at
            1.5 modules, with 25 % fewer centres).
    """

    max_seconds: float = 15.0
    cameras: tuple[str, ...] | None = None
    min_points: int = 40
    scales_per_msm: int = 3
    min_module_projector_px: float = 2.0
    min_side_fraction: float = 1.0 / 12.0
    max_side_fraction: float = 1.0 / 4.0
    edge_margin: float = 0.04
    min_gap_modules: float = 1.5

    def __post_init__(self) -> None:
        if not 0.0 < self.max_seconds <= 600.0:
            raise ValueError(f"max_seconds must be in (0, 600], got {self.max_seconds}")
        if self.min_points < 0 or self.scales_per_msm < 1:
            raise ValueError("min_points must be >= 0 and scales_per_msm >= 1")
        if not 0.0 < self.min_side_fraction <= self.max_side_fraction <= 1.0:
            raise ValueError("need 0 < min_side_fraction <= max_side_fraction <= 1")
        if not self.min_module_projector_px >= 1.0:
            raise ValueError(f"min_module_projector_px must be at least 1, got {self.min_module_projector_px}")
        if not 0.0 <= self.edge_margin < 0.4:
            raise ValueError(f"edge_margin must be in [0, 0.4), got {self.edge_margin}")
        if not 0.0 <= self.min_gap_modules <= 8.0:
            raise ValueError(f"min_gap_modules must be in [0, 8], got {self.min_gap_modules}")


@dataclass(frozen=True)
class CameraFootprint:
    """Where one camera looks, in projector pixels, and how large a projector pixel is there.

    Attributes:
        camera: camera name.
        surface: 0 for the floor, k for the calibration's k-th other plane.
        polygon: the camera's view in projector pixels, ``(N, 2)`` convex hull.
        camera_px_per_projector_px: smallest and largest stretch of a projector pixel in
            the camera's image, at the footprint's centre.
        points: calibrated points the camera has.
    """

    camera: str
    surface: int
    polygon: np.ndarray
    camera_px_per_projector_px: tuple[float, float]
    points: int


@dataclass(frozen=True)
class DensePlan:
    """The extra arrays for one camera: their centres and the marker sides shown."""

    footprint: CameraFootprint
    centres: list[np.ndarray]  # one (n <= markers_per_array, 2) array of projector pixels per extra array
    sides_px: tuple[float, ...]  # marker sides in projector pixels, ascending


def target_cameras(calibration, options: DensifyOptions) -> list[str]:
    """The cameras to densify for (see ``DensifyOptions.cameras``); ValueError for a
    named camera that has no pose to plan from."""
    if options.cameras is not None:
        for name in options.cameras:
            if name not in calibration.poses:
                reason = calibration.failed.get(name, "not in the calibration")
                raise ValueError(f"camera {name} has no pose to plan from ({reason}); calibrate it first")
        return list(options.cameras)
    chosen = []
    for name in calibration.registered:
        metrics = calibration.metrics[name]
        if metrics.weak or metrics.inliers < options.min_points:
            chosen.append(name)
    for name, reason in calibration.failed.items():
        log.warning("camera %s is not registered (%s): no pose to plan its densification from", name, reason)
    return chosen


def camera_footprint(name: str, calibration, intrinsics, tracks, markers, options: DensifyOptions) -> CameraFootprint:
    """The footprint of camera ``name`` in projector pixels (ValueError when it cannot be
    cast: no surface with enough calibrated points, or a view that misses it)."""
    if intrinsics.resolution is None:
        raise ValueError(f"camera {name}: its intrinsics file gives no image size")
    ids, _ = tracks.observations(name)
    surfaces = _surfaces(calibration)
    nearest = _nearest_surface(calibration.points, surfaces)
    seen = np.isin(calibration.point_ids, ids)
    if not seen.any():
        raise ValueError(f"camera {name}: none of its points is in the calibration")
    surface = int(np.bincount(nearest[seen], minlength=len(surfaces)).argmax())
    on_surface = nearest == surface
    if on_surface.sum() < MIN_SURFACE_POINTS:
        raise ValueError(f"camera {name}: only {int(on_surface.sum())} calibrated points on its surface "
                         f"(need {MIN_SURFACE_POINTS})")
    frame = _SurfaceFrame(*surfaces[surface])
    homography = _projector_to_surface(markers.pixels(calibration.point_ids[on_surface]),
                                       frame.coordinates(calibration.points[on_surface]))
    rotation, translation = calibration.poses[name]
    view = _CameraView(np.asarray(rotation, float), np.asarray(translation, float).ravel(), intrinsics)
    polygon = _view_polygon(view, frame, homography, options.edge_margin)
    stretch = _stretch(view, frame, homography, polygon.mean(axis=0))
    return CameraFootprint(name, surface, polygon, stretch, int(seen.sum()))


def plan_arrays(footprint: CameraFootprint, sequence: Sequence, image_size: tuple[int, int], max_arrays: int,
                options: DensifyOptions) -> DensePlan:
    """Extra arrays filling ``footprint``, at most ``max_arrays`` of them (ValueError when
    not even one marker fits the camera's view and the projector image)."""
    sides = _marker_sides(footprint, sequence, image_size, options)
    grid_cells = sequence.markers.grid_cells
    gap = max(1.0, max(sequence.min_gap_modules, options.min_gap_modules) * sides[-1] / grid_cells)
    pitch = float(math.ceil(sides[-1] + gap))
    capacity = sequence.layout.markers_per_array
    for offsets in range(max(1, math.isqrt(max_arrays)), 0, -1):
        arrays = _offset_arrays(footprint.polygon, pitch, offsets, sides, sequence, capacity)
        if arrays and len(arrays) <= max_arrays:
            return DensePlan(footprint, arrays, sides)
    raise ValueError(f"camera {footprint.camera}: no marker of {sides[0]:g} px or more fits its view in the "
                     f"projector image within {max_arrays} array(s)")


def densified_sequence(sequence: Sequence, plans: list[DensePlan]) -> Sequence:
    """``sequence`` with the arrays of ``plans`` appended, showing only those."""
    layout = sequence.layout
    capacity = layout.markers_per_array
    new_sides = sorted({side for plan in plans for side in plan.sides_px})
    scales = list(layout.scales)
    for side in new_sides:
        if not any(math.isclose(layout.marker_side(s), side) for s in scales):
            scales.append(side / layout.marker_px)
    extra = [centres for plan in plans for centres in plan.centres]
    dense_layout = MsmLayout(projector=layout.projector, grid=layout.grid, arrays=layout.arrays + len(extra),
                             scales=tuple(scales), marker_px=layout.marker_px, margin_px=layout.margin,
                             snap_to_pixels=layout.snap_to_pixels)
    centres = [sequence.centres]
    shown = []
    array = layout.arrays
    for plan in plans:
        for used in plan.centres:
            filled = np.repeat(used[:1], capacity, axis=0)
            filled[:len(used)] = used
            centres.append(filled[None])
            unused = tuple(range(len(used), capacity))
            for side in plan.sides_px:
                scale_index = next(k for k, s in enumerate(scales) if math.isclose(layout.marker_side(s), side))
                outside = tuple(int(m) for m in np.flatnonzero(outside_image(used, side, layout.projector)))
                shown.append(ShownPattern(array, scale_index, tuple(sorted(set(outside + unused)))))
            array += 1
    return reassembled(sequence, dense_layout, np.concatenate(centres), shown)


def densify(results: str | os.PathLike, sequence: Sequence,
            options: DensifyOptions | None = None) -> tuple[Sequence, list[DensePlan]]:
    """The densified sequence for the calibration in the folder ``results`` (made from a
    recording of ``sequence``) and the plan per camera; ``(None, [])`` when no camera
    needs it. A camera that cannot be planned for is logged and left out."""
    from calibproj.formats.calibration import Calibration
    from calibproj.formats.results import TRACKS_FILE, resolve_intrinsics
    from calibproj.sequence.projected import projected_markers
    from calibproj.formats.tracks import Tracks

    options = options or DensifyOptions()
    folder = Path(results)
    calibration = Calibration.load(folder)
    tracks = Tracks.read(folder / TRACKS_FILE)
    markers = projected_markers(sequence)
    if tracks.markers_per_array not in (None, markers.markers_per_array) or \
            (len(tracks.point_ids) and tracks.point_ids.max() >= markers.point_count):
        raise ValueError(f"{folder}: its tracks do not come from this sequence (point ids or markers per array "
                         f"differ); give the sequence the results were calibrated from")
    names = target_cameras(calibration, options)
    if not names:
        return None, []
    intrinsics = resolve_intrinsics(folder, None)
    footprints = []
    for name in names:
        try:
            if name not in intrinsics:
                raise ValueError(f"camera {name}: no intrinsics file in {folder / 'intrinsics'}")
            footprints.append(camera_footprint(name, calibration, intrinsics[name], tracks, markers, options))
        except ValueError as error:
            if options.cameras is not None:
                raise
            log.warning("%s; not densified", error)
    if not footprints:
        return None, []
    budget = _pattern_budget(sequence, options)
    plans = []
    for footprint in footprints:
        share = budget // (len(footprints) * options.scales_per_msm)
        plan = plan_arrays(footprint, sequence, intrinsics[footprint.camera].resolution, max(share, 1), options)
        plans.append(plan)
    dense = densified_sequence(sequence, plans)
    if dense.duration_s > options.max_seconds + 1e-9:
        raise ValueError(f"the extra projection would last {dense.duration_s:.1f} s, more than {options.max_seconds:g} s: "
                         f"densify fewer cameras at once (--cameras) or allow more time")
    return dense, plans


# -- geometry ------------------------------------------------------------------------


class _SurfaceFrame:
    """A plane ``n . X = offset`` of the floor frame with 2D coordinates on it."""

    def __init__(self, normal: np.ndarray, offset: float) -> None:
        self.normal = np.asarray(normal, float) / np.linalg.norm(normal)
        self.offset = float(offset)
        self.origin = self.normal * self.offset
        helper = np.array([1.0, 0.0, 0.0]) if abs(self.normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        self.e1 = helper - self.normal * (helper @ self.normal)
        self.e1 /= np.linalg.norm(self.e1)
        self.e2 = np.cross(self.normal, self.e1)

    def coordinates(self, points: np.ndarray) -> np.ndarray:
        relative = np.asarray(points, float) - self.origin
        return np.stack([relative @ self.e1, relative @ self.e2], axis=-1)

    def points(self, coordinates: np.ndarray) -> np.ndarray:
        coordinates = np.asarray(coordinates, float)
        return self.origin + coordinates[:, :1] * self.e1 + coordinates[:, 1:2] * self.e2


class _CameraView:
    """A calibrated camera: world-to-camera pose and its intrinsics."""

    def __init__(self, rotation: np.ndarray, translation: np.ndarray, intrinsics) -> None:
        self.rotation, self.translation, self.intrinsics = rotation, translation, intrinsics
        self.centre = -rotation.T @ translation

    def rays(self, pixels: np.ndarray) -> np.ndarray:
        undistorted = self.intrinsics.undistort_points(pixels)
        normalised = np.linalg.solve(self.intrinsics.K, np.c_[undistorted, np.ones(len(undistorted))].T).T
        return normalised @ self.rotation  # rows: R^T d

    def project(self, points: np.ndarray) -> np.ndarray:
        """Undistorted pixels of world points."""
        camera = points @ self.rotation.T + self.translation
        pixels = camera @ self.intrinsics.K.T
        return pixels[:, :2] / pixels[:, 2:]


def _surfaces(calibration) -> list[tuple[np.ndarray, float]]:
    planes = [(np.asarray(p.normal, float), float(p.offset)) for p in calibration.planes]
    return [(np.array([0.0, 0.0, 1.0]), 0.0)] + planes


def _nearest_surface(points: np.ndarray, surfaces: list[tuple[np.ndarray, float]]) -> np.ndarray:
    distances = np.stack([np.abs(points @ (n / np.linalg.norm(n)) - d / np.linalg.norm(n)) for n, d in surfaces])
    return distances.argmin(axis=0)


def _projector_to_surface(pixels: np.ndarray, coordinates: np.ndarray) -> np.ndarray:
    import cv2

    homography, _ = cv2.findHomography(pixels.astype(np.float64), coordinates.astype(np.float64), cv2.LMEDS)
    if homography is None:
        raise ValueError("the calibrated points do not determine the projector's map onto their surface")
    return homography


def _apply(homography: np.ndarray, points: np.ndarray) -> np.ndarray:
    mapped = np.c_[points, np.ones(len(points))] @ homography.T
    return mapped[:, :2] / mapped[:, 2:]


def _view_polygon(view: _CameraView, frame: _SurfaceFrame, homography: np.ndarray, margin: float) -> np.ndarray:
    import cv2

    width, height = view.intrinsics.resolution
    u = np.linspace(margin * width, (1.0 - margin) * width - 1.0, FOOTPRINT_SAMPLES)
    v = np.linspace(margin * height, (1.0 - margin) * height - 1.0, FOOTPRINT_SAMPLES)
    grid = np.stack(np.meshgrid(u, v), axis=-1).reshape(-1, 2)
    rays = view.rays(grid)
    along = rays @ frame.normal
    reach = (frame.offset - view.centre @ frame.normal) / np.where(np.abs(along) > 1e-12, along, np.nan)
    hits = np.isfinite(reach) & (reach > 0)
    if hits.sum() < 3:
        raise ValueError(f"camera {view.intrinsics.name}: its view does not reach its surface")
    points = view.centre + reach[hits, None] * rays[hits]
    projector = _apply(np.linalg.inv(homography), frame.coordinates(points))
    return cv2.convexHull(projector.astype(np.float32)).reshape(-1, 2).astype(np.float64)


def _stretch(view: _CameraView, frame: _SurfaceFrame, homography: np.ndarray, at: np.ndarray) -> tuple[float, float]:
    """Singular values of d(camera px)/d(projector px) at projector pixel ``at``."""
    probe = np.array([at, at + [1.0, 0.0], at + [0.0, 1.0]])
    pixels = view.project(frame.points(_apply(homography, probe)))
    jacobian = np.stack([pixels[1] - pixels[0], pixels[2] - pixels[0]], axis=1)
    values = np.linalg.svd(jacobian, compute_uv=False)
    return float(values.min()), float(values.max())


def _marker_sides(footprint: CameraFootprint, sequence: Sequence, image_size: tuple[int, int],
                  options: DensifyOptions) -> tuple[float, ...]:
    """Marker sides (projector px, even integers) for the camera: from the smallest that
    it decodes well to the largest that still leaves room for many."""
    short = min(image_size)
    stretch_min, stretch_max = footprint.camera_px_per_projector_px
    smallest = max(options.min_module_projector_px * sequence.markers.grid_cells,
                   options.min_side_fraction * short / stretch_min)
    largest = max(smallest, options.max_side_fraction * short / stretch_max)
    sides = np.geomspace(smallest, largest, options.scales_per_msm)
    even = sorted({float(2 * math.ceil(side / 2.0)) for side in sides})
    return tuple(even)


def _offset_arrays(polygon: np.ndarray, pitch: float, offsets: int, sides: tuple[float, ...], sequence: Sequence,
                   capacity: int) -> list[np.ndarray]:
    """Centres of ``offsets``^2 lattices of ``pitch`` px, each shifted by a fraction of
    the pitch, kept where the smallest marker lies inside the view and the projector
    image, cut into arrays of at most ``capacity`` markers."""
    import cv2

    contour = polygon.astype(np.float32).reshape(-1, 1, 2)
    low, high = polygon.min(axis=0), polygon.max(axis=0)
    half = 0.5 * sides[0]
    arrays = []
    for k in range(offsets * offsets):
        shift = (np.array([k % offsets, k // offsets], float) + 0.5) / offsets * pitch
        xs = np.arange(low[0] + shift[0] - pitch, high[0] + pitch, pitch)
        ys = np.arange(low[1] + shift[1] - pitch, high[1] + pitch, pitch)
        lattice = snap_centres(np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2), sequence.layout.marker_px)
        inside = [cv2.pointPolygonTest(contour, (float(x), float(y)), True) >= half for x, y in lattice]
        kept = lattice[np.asarray(inside, bool) & ~outside_image(lattice, sides[0], sequence.projector)]
        arrays.extend(kept[i:i + capacity] for i in range(0, len(kept), capacity))
    return [array for array in arrays if len(array)]


def _pattern_budget(sequence: Sequence, options: DensifyOptions) -> int:
    budget = pattern_budget(sequence, options.max_seconds)
    if budget < options.scales_per_msm:
        raise ValueError(f"{options.max_seconds:g} s leave no time for patterns: the light codes and reference "
                         f"frames alone take {overhead_seconds(sequence):.1f} s")
    return budget
