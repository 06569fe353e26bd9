"""Where every camera pixel looks in the projector image, through the floor.

For a planar floor z = 0, a device's pinhole projection of floor points is the
homography ``H = K [r1 r2 t]`` (floor ``(x, y, 1)`` to homogeneous pixels). A camera
pixel is first undistorted (OpenCV model, iterated to convergence), then carried to
the projector image by ``H_projector @ inv(H_camera)``. Both homographies and
``cv2.remap`` use OpenCV's pixel convention (the centre of the top-left pixel is
(0, 0)), so no half-pixel shift appears anywhere. In a room with boxes or an uneven
floor, each camera ray is traced to the first surface it meets instead.

A camera pixel sees the floor through the lens's blur and integrates the light over
its area. Both are applied before sampling, in the projector image: the pyramid of
the projector image (``calibproj.simulate.atlas``) is read at a fractional level (two
levels blended) whose blur has the variance of the pixel box plus the optical blur,
``(1/12 + blur_px**2) * |det J|`` projector pixels squared (``J`` the Jacobian of the
camera -> projector mapping). Point samples of a Gaussian-like blur are free of
aliasing (edges rendered at any sub-pixel phase land where they should) only if the
blur is at least ``ANTI_ALIAS_STD_PX`` wide along the most compressed direction, so
the blur never goes below that, even when the optical blur is off. Where the camera
magnifies the projector image, level 0 is read with bilinear interpolation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibproj.simulate.atlas import AtlasLayout, level_variance
from calibproj.simulate.scene import Camera, Floor, Projector

# Pixels whose undistorted position, distorted again, misses them by more than this
# lie where the lens model is not one-to-one; they are rendered black.
LENS_MODEL_TOLERANCE_PX = 1e-3
# Outside every level: remap's constant border (black).
OUTSIDE = -16.0
# Deepest pyramid level a renderer builds (1/32 of the projector resolution).
MAX_LEVELS = 6
# Smallest blur (standard deviation, in samples) kept along any direction: an edge
# sampled through a Gaussian of std s moves with its sub-pixel phase by a share of
# about exp(-2 pi^2 s^2) of a pixel, 0.7 % at 0.5 (a box of one pixel, 0.29, is
# exact only as a box, which a pyramid cannot give).
ANTI_ALIAS_STD_PX = 0.5


def floor_homography(K: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``K [r1 r2 t]``: floor points ``(x, y, 1)`` (z = 0) to homogeneous pixels."""
    return K @ np.column_stack([R[:, 0], R[:, 1], t])


@dataclass(frozen=True, eq=False)
class FloorView:
    """Projector coordinates seen by every sample of a camera (one per pixel, or
    ``supersample`` x ``supersample`` per pixel).

    Attributes:
        projector_x, projector_y: projector pixel coordinates ``(H, W)`` of the floor
            point each sample sees, NaN where it sees no floor.
        on_floor: the sample's ray meets the floor rectangle in front of the camera.
        in_image: ... and that floor point receives the projector's image.
        area: ``|det J|``, projector pixels squared covered by one sample; NaN off the floor.
        stretch: largest squared singular value of ``J``: projector pixels squared
            per sample along the most compressed direction; NaN off the floor.
        floor_x, floor_y: the floor point each sample sees (metres), NaN off the floor.
        floor_footprint: side of the floor square (metres) one sample covers, NaN off it.
        surface: per sample the surface it sees (``calibproj.simulate.boxes``: 0 the
            floor, -1 none), or None in a room without boxes.
        reflectance: per sample the box's albedo times how much more or less projector
            light its face receives than the floor would (1 on the floor), or None.
        shadow: per sample whether a box hides the point it sees from the projector
            (it gets room light only), or None.
    """

    projector_x: np.ndarray
    projector_y: np.ndarray
    on_floor: np.ndarray
    in_image: np.ndarray
    area: np.ndarray
    stretch: np.ndarray
    floor_x: np.ndarray
    floor_y: np.ndarray
    floor_footprint: np.ndarray
    surface: np.ndarray | None = None
    reflectance: np.ndarray | None = None
    shadow: np.ndarray | None = None

    def prefilter_variance(self, blur_samples: float) -> np.ndarray:
        """Per-axis variance (projector pixels squared) of the blur each sample needs:
        its box plus a Gaussian optical blur of ``blur_samples``, and no less than
        ``ANTI_ALIAS_STD_PX`` along the most compressed direction."""
        physical = self.area * (1.0 / 12.0 + blur_samples**2)
        return np.maximum(physical, ANTI_ALIAS_STD_PX**2 * self.stretch)


def sample_grid(resolution: tuple[int, int], supersample: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates ``(H * s, W * s)`` of the ``s`` x ``s`` sample centres of every pixel."""
    width, height = resolution
    offsets = (np.arange(supersample) + 0.5) / supersample - 0.5
    xs = (np.arange(width)[:, None] + offsets[None, :]).ravel()
    ys = (np.arange(height)[:, None] + offsets[None, :]).ravel()
    return np.meshgrid(xs, ys)


def floor_view(camera: Camera, projector: Projector, floor: Floor, supersample: int = 1,
               scene_boxes: tuple = ()) -> FloorView:
    """Trace every sample of ``camera`` to the floor (or a box standing on it) and into
    the projector image."""
    if scene_boxes or floor.relief is not None:
        return _view_of_surfaces(camera, projector, floor, supersample, scene_boxes)
    grid_x, grid_y = sample_grid(camera.resolution, supersample)
    pixels = np.column_stack([grid_x.ravel(), grid_y.ravel()])
    intrinsics = camera.intrinsics
    undistorted = intrinsics.undistort_points(pixels)
    modelled = np.linalg.norm(intrinsics.distort_points(undistorted) - pixels, axis=1) < LENS_MODEL_TOLERANCE_PX
    floor_from_camera = np.linalg.inv(floor_homography(camera.K, camera.R, camera.t))
    on_floor_h = np.column_stack([undistorted, np.ones(len(pixels))]) @ floor_from_camera.T
    projected = on_floor_h @ floor_homography(projector.K, projector.R, projector.t).T
    with np.errstate(divide="ignore", invalid="ignore"):
        floor_xy = on_floor_h[:, :2] / on_floor_h[:, 2:]
        projector_xy = projected[:, :2] / projected[:, 2:]
        # The third coordinate of on_floor_h is 1 / (depth of the floor point in the
        # camera): positive in front of it. Given that, the third coordinate of
        # ``projected`` has the sign of the depth in the projector.
        half_size = 0.5 * np.asarray(floor.size_m)
        on_floor = (modelled & (on_floor_h[:, 2] > 0) & (projected[:, 2] > 0)
                    & np.all(np.abs(floor_xy) <= half_size, axis=1))
    projector_xy[~on_floor] = np.nan
    projector_xy = projector.buffer_pixels(projector_xy)
    floor_xy[~on_floor] = np.nan
    shape = grid_x.shape
    x, y = projector_xy[:, 0].reshape(shape), projector_xy[:, 1].reshape(shape)
    floor_x, floor_y = floor_xy[:, 0].reshape(shape), floor_xy[:, 1].reshape(shape)
    footprint = np.sqrt(_area_and_stretch(floor_x, floor_y)[0])
    return FloorView(x, y, on_floor.reshape(shape), _inside(x, y, projector), *_area_and_stretch(x, y),
                     floor_x, floor_y, footprint)


def _view_of_surfaces(camera: Camera, projector: Projector, floor: Floor, supersample: int,
                      scene_boxes: tuple) -> FloorView:
    """``floor_view`` ray by ray, in a room with boxes or an uneven floor: each sample
    sees the first surface its ray meets; a point the boxes hide from the projector is
    in shadow (no projected light). A relief's own shadows and shading are left out:
    its slopes stay below a degree."""
    from calibproj.simulate import boxes

    grid_x, grid_y = sample_grid(camera.resolution, supersample)
    shape = grid_x.shape
    pixels = np.column_stack([grid_x.ravel(), grid_y.ravel()])
    intrinsics = camera.intrinsics
    undistorted = intrinsics.undistort_points(pixels)
    modelled = np.linalg.norm(intrinsics.distort_points(undistorted) - pixels, axis=1) < LENS_MODEL_TOLERANCE_PX
    rays = np.column_stack([intrinsics.normalize(undistorted), np.ones(len(pixels))]) @ camera.R
    points, surface = boxes.first_hits(camera.center, rays, scene_boxes, floor)
    half_size = 0.5 * np.asarray(floor.size_m)
    with np.errstate(invalid="ignore"):
        seen = modelled & (surface >= 0) & ((surface != boxes.FLOOR) | np.all(np.abs(points[:, :2]) <= half_size, axis=1))
    in_projector = points @ projector.R.T + projector.t
    with np.errstate(divide="ignore", invalid="ignore"):
        projector_xy = (in_projector @ projector.K.T)[:, :2] / in_projector[:, 2:]
    seen &= in_projector[:, 2] > 0
    projector_xy = projector.buffer_pixels(np.where(seen[:, None], projector_xy, np.nan))
    lit = seen & ~boxes.hidden(projector.center, np.nan_to_num(points), scene_boxes)
    reflectance = np.ones(len(points))
    toward = projector.center - points
    toward /= np.maximum(np.linalg.norm(toward, axis=1, keepdims=True), 1e-12)
    for surface_id in np.unique(surface[seen & (surface != boxes.FLOOR)]):
        chosen = seen & (surface == surface_id)
        normal, _ = boxes.surface_plane(scene_boxes, int(surface_id))
        with np.errstate(divide="ignore", invalid="ignore"):
            incidence = np.clip((toward[chosen] @ normal) / np.maximum(toward[chosen, 2], 1e-6), 0.0, 2.0)
        reflectance[chosen] = scene_boxes[(int(surface_id) - 1) // len(boxes.FACES)].albedo * incidence
    projector_xy[~seen] = np.nan
    points[~seen] = np.nan
    x, y = projector_xy[:, 0].reshape(shape), projector_xy[:, 1].reshape(shape)
    floor_x, floor_y = points[:, 0].reshape(shape), points[:, 1].reshape(shape)
    footprint = np.sqrt(_area_and_stretch(floor_x, floor_y)[0])
    in_image = _inside(x, y, projector) & lit.reshape(shape)
    return FloorView(x, y, seen.reshape(shape), in_image, *_area_and_stretch(x, y), floor_x, floor_y, footprint,
                     surface.reshape(shape), reflectance.reshape(shape), (seen & ~lit).reshape(shape))


def _inside(x: np.ndarray, y: np.ndarray, projector: Projector) -> np.ndarray:
    """Projector coordinates inside the image, which spans [-0.5, size - 0.5] (OpenCV)."""
    width, height = projector.resolution
    with np.errstate(invalid="ignore"):
        return (x >= -0.5) & (x <= width - 0.5) & (y >= -0.5) & (y <= height - 0.5)


def _area_and_stretch(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``|det J|`` and the largest squared singular value of ``J`` per sample."""
    dx_du, dx_dv = _gradient(x)
    dy_du, dy_dv = _gradient(y)
    area = np.abs(dx_du * dy_dv - dx_dv * dy_du)
    frobenius = dx_du**2 + dx_dv**2 + dy_du**2 + dy_dv**2
    stretch = 0.5 * (frobenius + np.sqrt(np.maximum(frobenius**2 - 4.0 * area**2, 0.0)))
    return area, stretch


def _gradient(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Derivatives along image x and y per sample; one-sided at edges and next to NaN."""
    if min(values.shape) < 2:
        return np.full(values.shape, np.nan), np.full(values.shape, np.nan)
    d_dv, d_du = np.gradient(values)
    # np.gradient's central differences are NaN next to a NaN; fall back on one side.
    forward_u = np.diff(values, axis=1, append=np.nan)
    backward_u = np.diff(values, axis=1, prepend=np.nan)
    forward_v = np.diff(values, axis=0, append=np.nan)
    backward_v = np.diff(values, axis=0, prepend=np.nan)
    d_du = np.where(np.isfinite(d_du), d_du, np.where(np.isfinite(forward_u), forward_u, backward_u))
    d_dv = np.where(np.isfinite(d_dv), d_dv, np.where(np.isfinite(forward_v), forward_v, backward_v))
    return d_du, d_dv


def pyramid_levels_needed(view: FloorView, blur_samples: float) -> int:
    """Levels the pyramid needs so that the blurriest sample inside the projector's
    image is matched (beyond it the floor is dark at any level)."""
    variance = view.prefilter_variance(blur_samples)
    variance = variance[view.in_image & np.isfinite(variance)]
    if variance.size == 0:
        return 1
    # level_variance(l) = 4**l / 2 - 1 / 3; invert it for the largest footprint.
    level = 0.5 * math.log2(2.0 * (float(variance.max()) + 1.0 / 3.0))
    return int(min(MAX_LEVELS, max(1, math.ceil(level) + 1)))


@dataclass(frozen=True, eq=False)
class CameraSampler:
    """Reads a camera image out of a projector atlas: two fixed-point remaps (the
    levels below and above each pixel's footprint) and a per-pixel blend.

    Attributes:
        resolution: camera image ``(width, height)``.
        supersample: samples per pixel along each axis (1: one sample at the centre).
        lower_maps, upper_maps: ``cv2.convertMaps`` output for the two levels.
        weights: per-sample weights of the lower and upper level (``float32``),
            ``None`` when every sample reads the lower level only.
    """

    resolution: tuple[int, int]
    supersample: int
    lower_maps: tuple[np.ndarray, np.ndarray]
    upper_maps: tuple[np.ndarray, np.ndarray] | None
    weights: tuple[np.ndarray, np.ndarray] | None

    @classmethod
    def from_view(cls, view: FloorView, layout: AtlasLayout, resolution: tuple[int, int],
                  supersample: int, blur_px: float) -> CameraSampler:
        """A sampler for ``view`` whose samples are ``1 / supersample`` pixels apart,
        with an optical blur of ``blur_px`` camera pixels."""
        lower, weight = _levels(view.prefilter_variance(blur_px * supersample), layout.levels)
        lower_maps = _fixed_maps(layout, lower, view)
        if not np.any(weight > 0):
            return cls(tuple(resolution), supersample, lower_maps, None, None)
        upper_maps = _fixed_maps(layout, np.minimum(lower + 1, layout.levels - 1), view)
        weights = ((1.0 - weight).astype(np.float32), weight.astype(np.float32))
        return cls(tuple(resolution), supersample, lower_maps, upper_maps, weights)

    def sample(self, atlas: np.ndarray) -> np.ndarray:
        """Projector light seen by every camera pixel, ``float32`` in [0, 1]."""
        import cv2

        lower = cv2.remap(atlas, *self.lower_maps, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        if self.upper_maps is not None:
            upper = cv2.remap(atlas, *self.upper_maps, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                              borderValue=0)
            lower = cv2.blendLinear(lower, upper, *self.weights)
        if self.supersample > 1:
            # An integer factor: INTER_AREA averages each pixel's samples exactly.
            lower = cv2.resize(lower, self.resolution, interpolation=cv2.INTER_AREA)
        return lower


def _levels(variance: np.ndarray, levels: int) -> tuple[np.ndarray, np.ndarray]:
    """Per sample, the level below the blur ``variance`` asks for and the weight of the
    level above, so that the blend has that variance."""
    target = np.nan_to_num(variance, nan=0.0)
    continuous = 0.5 * np.log2(2.0 * (target + 1.0 / 3.0))
    lower = np.clip(np.floor(continuous), 0, levels - 1).astype(np.int64)
    low_variance = level_variance(lower)
    high_variance = level_variance(lower + 1)
    weight = np.clip((target - low_variance) / (high_variance - low_variance), 0.0, 1.0)
    weight[lower >= levels - 1] = 0.0
    return lower, weight


def _fixed_maps(layout: AtlasLayout, level: np.ndarray, view: FloorView) -> tuple[np.ndarray, np.ndarray]:
    """Atlas coordinates of every sample at its ``level``, as remap's fixed-point maps;
    samples off the floor or in a box's shadow read outside the atlas (black)."""
    import cv2

    map_x = np.full(level.shape, OUTSIDE, dtype=np.float64)
    map_y = np.full(level.shape, OUTSIDE, dtype=np.float64)
    receives = view.on_floor if view.shadow is None else view.on_floor & ~view.shadow
    for index in np.unique(level[receives]):
        chosen = receives & (level == index)
        map_x[chosen], map_y[chosen] = layout.atlas_coordinates(
            int(index), view.projector_x[chosen], view.projector_y[chosen])
    return cv2.convertMaps(map_x.astype(np.float32), map_y.astype(np.float32), cv2.CV_16SC2)
