"""The report's plots, drawn on matplotlib's Agg canvas (no display, no pyplot state).

Each function returns PNG bytes. Scene plots use the calibration's floor frame (z up,
floor z = 0); per-camera plots use image pixels with y pointing down, as OpenCV.
"""

from __future__ import annotations

import io
from collections.abc import Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from calibproj.formats.calibration import Calibration
from calibproj.report.data import CameraView

DEFAULT_DPI = 80
# Points drawn in the scene plots at most (every k-th point beyond that).
MAX_SCENE_POINTS = 4000
# Frustum depth as a share of the scene's extent.
FRUSTUM_SHARE = 0.12
# The largest camera-centre uncertainty circle is drawn at this share of the scene.
UNCERTAINTY_SHARE = 0.04
# Coverage grid: cells along the longer image side.
COVERAGE_CELLS = 16
# Mean-residual arrows: cells along the longer image side, and the observations a cell
# needs for its mean to be drawn.
ARROW_CELLS = 10
MIN_CELL_OBSERVATIONS = 5
FAILED_COLOUR = "#c0392b"


def png_bytes(figure: Figure, dpi: int = DEFAULT_DPI) -> bytes:
    FigureCanvasAgg(figure)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()


def camera_colours(count: int) -> list[tuple[float, float, float, float]]:
    from matplotlib import colormaps

    cmap = colormaps["tab10" if count <= 10 else "tab20"]
    return [cmap(i % cmap.N) for i in range(count)]


# -- scene --------------------------------------------------------------------------------


def frustum(view: CameraView, depth: float) -> np.ndarray:
    """The camera centre and the four image corners at ``depth`` in front of it, world frame (5, 3)."""
    R, t = view.pose
    width, height = view.image_size()
    corners = np.array([[-0.5, -0.5], [width - 0.5, -0.5], [width - 0.5, height - 0.5], [-0.5, height - 0.5]])
    rays = np.column_stack([view.intrinsics.normalize(corners), np.ones(4)]) * depth
    centre = -R.T @ t
    return np.vstack([centre, rays @ R + centre])  # R^T ray for each row


def scene_extent(calibration: Calibration) -> tuple[np.ndarray, float]:
    centres = np.array([calibration.center(name) for name in calibration.poses]).reshape(-1, 3)
    everything = np.vstack([centres, calibration.points.reshape(-1, 3)])
    low, high = everything.min(axis=0), everything.max(axis=0)
    return everything, float(np.max(high - low)) or 1.0


def floor_outline(points: np.ndarray) -> np.ndarray:
    """Convex hull of the points' floor positions (x, y), the area the projector covered."""
    import cv2

    hull = cv2.convexHull(np.asarray(points[:, :2], dtype=np.float32))
    return hull.reshape(-1, 2).astype(float)


def plane_outlines(calibration: Calibration, extent: float) -> list[np.ndarray]:
    """Per plane besides the floor (``Calibration.planes``), the convex hull of the points
    within 1 % of the scene's extent of it, as a 3D polygon (empty when too few)."""
    import cv2

    out = []
    for plane in calibration.planes:
        n = np.array(plane.normal, dtype=float)
        n /= np.linalg.norm(n)
        near = np.abs(calibration.points @ n - plane.offset) < 0.01 * extent
        if near.sum() < 3:
            out.append(np.zeros((0, 3)))
            continue
        u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        flat = np.column_stack([calibration.points[near] @ u, calibration.points[near] @ v]).astype(np.float32)
        hull = cv2.convexHull(flat).reshape(-1, 2).astype(float)
        out.append(plane.offset * n + hull[:, :1] * u + hull[:, 1:] * v)
    return out


def subsampled(points: np.ndarray) -> np.ndarray:
    step = max(1, int(np.ceil(len(points) / MAX_SCENE_POINTS)))
    return points[::step]


def drawable_views(views: Sequence[CameraView]) -> list[CameraView]:
    return [v for v in views if v.registered and v.intrinsics is not None]


def scene_3d(calibration: Calibration, views: Sequence[CameraView], dpi: int = DEFAULT_DPI) -> bytes:
    """Cameras as frusta, the floor rectangle under the points and the points, in 3D."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    figure = Figure(figsize=(10.0, 8.0))
    axes = figure.add_subplot(projection="3d")
    everything, extent = scene_extent(calibration)
    points = subsampled(calibration.points)
    if len(points) >= 3:
        on_floor = np.abs(calibration.points[:, 2]) < 0.01 * extent
        outline = floor_outline(calibration.points[on_floor] if on_floor.sum() >= 3 else calibration.points)
        floor = np.column_stack([outline, np.zeros(len(outline))])
        axes.add_collection3d(Poly3DCollection([floor], facecolor="#d9d9d9", edgecolor="#999999", alpha=0.35))
    for k, outline in enumerate(plane_outlines(calibration, extent)):
        if len(outline) >= 3:
            axes.add_collection3d(Poly3DCollection([outline], facecolor="#9ecae1", edgecolor="#3182bd", alpha=0.5))
            axes.text(*outline.mean(axis=0), f" plane {k + 1}", color="#3182bd", fontsize=8)
    if len(points):
        axes.scatter(points[:, 0], points[:, 1], points[:, 2], s=0.5, c="#666666", alpha=0.5, linewidths=0,
                     depthshade=False)
    drawable = drawable_views(views)
    for view, colour in zip(drawable, camera_colours(len(drawable))):
        corners = frustum(view, FRUSTUM_SHARE * extent)
        for i in range(1, 5):
            axes.plot(*corners[[0, i]].T, color=colour, linewidth=1)
        axes.plot(*corners[[1, 2, 3, 4, 1]].T, color=colour, linewidth=1.5)
        axes.text(*corners[0], f" {view.name}", color=colour, fontsize=8)
    low, high = everything.min(axis=0), everything.max(axis=0)
    axes.set_box_aspect(np.maximum(high - low, 1e-3 * extent))
    unit = _unit_label(calibration)
    axes.set_xlabel(f"x {unit}")
    axes.set_ylabel(f"y {unit}")
    axes.set_zlabel(f"z {unit}")
    axes.set_title("cameras, floor and points (floor frame, z up)")
    figure.subplots_adjust(left=0.0, right=0.95, bottom=0.02, top=0.96)
    return png_bytes(figure, dpi)


def uncertainty_magnification(views: Sequence[CameraView], extent: float) -> float:
    """Factor that brings the largest centre 3-sigma circle to UNCERTAINTY_SHARE of the
    scene's extent (1 when they are that large already, or there is no sigma)."""
    sigmas = [view.metrics.centre_sigma for view in views
              if view.metrics is not None and view.metrics.centre_sigma is not None and view.metrics.centre_sigma > 0]
    if not sigmas or not extent > 0:
        return 1.0
    return max(1.0, UNCERTAINTY_SHARE * extent / (3.0 * max(sigmas)))


def _uncertainty_circle(axes, view: CameraView, centre: np.ndarray, magnification: float, colour) -> None:
    """The centre's 3-sigma (worst axis) circle, magnified; dashed for a weak camera."""
    from matplotlib.patches import Circle

    metrics = view.metrics
    if metrics is None or metrics.centre_sigma is None or not metrics.centre_sigma > 0:
        return
    axes.add_patch(Circle(tuple(centre), 3.0 * metrics.centre_sigma * magnification, fill=False, color=colour,
                          linewidth=1.0, linestyle="--" if metrics.weak else "-"))


def scene_views(calibration: Calibration, views: Sequence[CameraView], dpi: int = DEFAULT_DPI) -> bytes:
    """Top view (x, y) and side view (x, z) of the cameras, their optical axes and the
    points; around each camera centre its 3-sigma uncertainty (worst axis, magnified as
    the legend says; dashed for a weak camera)."""
    figure = Figure(figsize=(12.0, 5.0))
    top, side = figure.subplots(1, 2)
    _, extent = scene_extent(calibration)
    points = subsampled(calibration.points)
    drawable = drawable_views(views)
    unit = _unit_label(calibration)
    magnification = uncertainty_magnification(drawable, extent)
    for axes, (i, j), title in ((top, (0, 1), "from above"), (side, (0, 2), "from the side (y towards the viewer)")):
        if len(points):
            axes.scatter(points[:, i], points[:, j], s=1, c="#777777", label="points")
        for view, colour in zip(drawable, camera_colours(len(drawable))):
            corners = frustum(view, FRUSTUM_SHARE * extent)
            axis_end = corners[1:].mean(axis=0)
            axes.plot(*corners[0, [i, j]], "o", color=colour, markersize=6)
            _uncertainty_circle(axes, view, corners[0, [i, j]], magnification, colour)
            axes.plot([corners[0, i], axis_end[i]], [corners[0, j], axis_end[j]], color=colour, linewidth=1.5)
            axes.annotate(view.name, corners[0, [i, j]], textcoords="offset points", xytext=(4, 4),
                          fontsize=8, color=colour)
        axes.set_aspect("equal", adjustable="datalim")
        axes.set_xlabel(f"{'xyz'[i]} {unit}")
        axes.set_ylabel(f"{'xyz'[j]} {unit}")
        axes.set_title(title)
        axes.grid(True, linewidth=0.3)
    top.text(0.01, 0.01, f"circles: camera centre 3 sigma (worst axis) x {magnification:.0f}; dashed: weak",
             transform=top.transAxes, fontsize=8, color="#444444")
    side.axhline(0.0, color="#999999", linewidth=1)
    for k, outline in enumerate(plane_outlines(calibration, extent)):
        if len(outline) >= 3:
            closed = np.vstack([outline, outline[:1]])
            top.plot(closed[:, 0], closed[:, 1], color="#3182bd", linewidth=1.2)
            side.plot(closed[:, 0], closed[:, 2], color="#3182bd", linewidth=1.2)
            top.annotate(f"plane {k + 1}", closed[0, :2], fontsize=8, color="#3182bd")
    figure.subplots_adjust(left=0.06, right=0.98, bottom=0.11, top=0.93, wspace=0.18)
    return png_bytes(figure, dpi)


# Levels of uncertainty.json's map the report draws, by the heights they stand for (m).
MAP_LEVELS_M = ((0.0, "floor", "floor"), (0.9, "table", "table, 0.9 m"), (1.7, "head", "head, 1.7 m"))


def uncertainty_maps(document: dict, calibration: Calibration, views: Sequence[CameraView],
                     dpi: int = DEFAULT_DPI) -> list[tuple[str, str, bytes]]:
    """The expected 3D error (1 sigma, worst axis; mm in a metric calibration) over the
    floor at the floor, table and head heights of uncertainty.json's map, one figure
    each (stem, label, PNG) on one colour scale, with the cameras seen from above; blank where
    fewer than two cameras see."""
    grid = document["map"]
    xs, ys, zs = (np.asarray(grid[axis], dtype=float) for axis in ("x", "y", "z"))
    sigma = np.array(grid["sigma"], dtype=float)
    if sigma.shape != (len(zs), len(ys), len(xs)) or not len(xs) or not len(ys) or not len(zs):
        raise ValueError(f"map: sigma of shape {sigma.shape} for {len(zs)} x {len(ys)} x {len(xs)} cells")
    metric = calibration.unit == "m"
    values = sigma * (1000.0 if metric else 1.0)
    scale = zs[-1] / 2.0 if zs[-1] > 0 else 1.0  # map heights stand for 0 to 2 m
    levels = [(int(np.argmin(np.abs(zs - height * scale))), stem, label) for height, stem, label in MAP_LEVELS_M]
    shown = values[[k for k, _, _ in levels]]
    top = float(np.nanpercentile(shown, 98)) if np.isfinite(shown).any() else 1.0
    step_x = xs[1] - xs[0] if len(xs) > 1 else 1.0
    step_y = ys[1] - ys[0] if len(ys) > 1 else 1.0
    extent = (xs[0] - step_x / 2, xs[-1] + step_x / 2, ys[0] - step_y / 2, ys[-1] + step_y / 2)
    drawable = drawable_views(views)
    out = []
    for k, stem, label in levels:
        figure = Figure(figsize=(5.2, 4.6), layout="constrained")
        axes = figure.subplots()
        image = axes.imshow(values[k], origin="lower", extent=extent, cmap="viridis", vmin=0.0, vmax=max(top, 1e-12),
                            interpolation="nearest")
        for view, colour in zip(drawable, camera_colours(len(drawable))):
            R, t = view.pose
            centre = -R.T @ t
            axes.plot(centre[0], centre[1], "o", color=colour, markersize=6, markeredgecolor="white")
            axes.annotate(view.name, centre[:2], textcoords="offset points", xytext=(4, 4), fontsize=8, color=colour)
        axes.set_title(f"{label} (z = {zs[k]:.2f})")
        axes.set_xlabel(f"x {_unit_label(calibration)}")
        axes.set_ylabel(f"y {_unit_label(calibration)}")
        axes.set_aspect("equal", adjustable="datalim")
        colour_bar = figure.colorbar(image, ax=axes, shrink=0.8)
        colour_bar.set_label("1 sigma, worst axis " + ("[mm]" if metric else "[unit]"))
        out.append((stem, label, png_bytes(figure, dpi)))
    return out


def _unit_label(calibration: Calibration) -> str:
    return "[m]" if calibration.unit == "m" else "[arbitrary unit]"


# -- errors of all cameras --------------------------------------------------------------------


def error_whiskers(means: Sequence[float], stds: Sequence[float]) -> np.ndarray:
    """Lower and upper whisker lengths, ``(2, N)``: one standard deviation, the lower
    stopping at zero (an error is never negative)."""
    means, stds = np.asarray(means, dtype=float), np.asarray(stds, dtype=float)
    return np.array([np.minimum(stds, means), stds])


def error_bars(views: Sequence[CameraView], dpi: int = DEFAULT_DPI) -> bytes:
    """Mean reprojection error per camera with its standard deviation; failed cameras marked."""
    figure = Figure(figsize=(max(6.0, 0.7 * len(views) + 2.0), 3.6))
    axes = figure.subplots()
    positions = np.arange(len(views))
    means = [v.metrics.mean_px if v.metrics and v.metrics.mean_px is not None else 0.0 for v in views]
    stds = [v.metrics.std_px if v.metrics and v.metrics.std_px is not None else 0.0 for v in views]
    colours = ["#2b7bba" if v.registered else FAILED_COLOUR for v in views]
    axes.bar(positions, means, yerr=error_whiskers(means, stds), color=colours, capsize=3)
    for position, view in zip(positions, views):
        if not view.registered:
            axes.text(position, 0.0, "failed", rotation=90, ha="center", va="bottom", color=FAILED_COLOUR)
    axes.set_xticks(positions, [v.name for v in views], rotation=30, ha="right")
    axes.set_ylabel("reprojection error [px]")
    axes.set_title("inlier reprojection error: mean (bar), std (whisker)")
    axes.grid(True, axis="y", linewidth=0.3)
    figure.tight_layout()  # camera names of any length below the bars
    return png_bytes(figure, dpi)


def brightness_trace(values: Sequence[float], frames_per_value: int, reason: str,
                     dpi: int = DEFAULT_DPI) -> bytes:
    """A failed camera's mean brightness over its video: the light codes (fast
    black/white flicker at the start and the end) should stand out of it."""
    figure = Figure(figsize=(10.0, 3.0))
    axes = figure.subplots()
    values = np.asarray(values, dtype=float)
    axes.plot(np.arange(len(values)) * frames_per_value, values, color="#2b7bba", linewidth=0.8)
    axes.set_xlabel("video frame")
    axes.set_ylabel("mean brightness")
    axes.set_title(_wrapped(reason, 110), fontsize=8)
    axes.grid(True, linewidth=0.3)
    figure.tight_layout()
    return png_bytes(figure, dpi)


def _wrapped(text: str, width: int) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(text, width)[:4])


# -- one camera -------------------------------------------------------------------------------


PANEL_SIZE = (5.0, 3.8)  # inches: one per-camera plot, readable at a phone's width


def camera_errors(view: CameraView, dpi: int = DEFAULT_DPI) -> bytes:
    """Histogram of one camera's reprojection errors (or why there is none)."""
    figure = Figure(figsize=PANEL_SIZE)
    axes = figure.subplots()
    if view.registered and len(view.residuals):
        _histogram(axes, view.errors, view.metrics)
    else:
        _empty(axes, "not registered: no reprojection errors" if not view.registered
               else "no observation of a reconstructed point")
    figure.tight_layout()
    return png_bytes(figure, dpi)


def camera_residuals(view: CameraView, dpi: int = DEFAULT_DPI) -> bytes:
    """One camera's residuals over its image (or why there are none)."""
    figure = Figure(figsize=PANEL_SIZE)
    axes = figure.subplots()
    if view.registered and len(view.residuals):
        _residual_map(figure, axes, view)
    else:
        _empty(axes, "no residuals to draw")
    figure.tight_layout()
    return png_bytes(figure, dpi)


def camera_coverage(view: CameraView, dpi: int = DEFAULT_DPI) -> bytes:
    """How one camera's observations cover its image."""
    figure = Figure(figsize=PANEL_SIZE)
    axes = figure.subplots()
    _coverage(figure, axes, view)
    figure.tight_layout()
    return png_bytes(figure, dpi)


def camera_detections(view: CameraView, thumbnail: np.ndarray, scale: float, array: int | None,
                      dpi: int = DEFAULT_DPI) -> bytes:
    """A frame of the camera's video with what was found in it: the detected MSM
    centres of the array it shows, where the calibration reprojects their points, the
    centres detected in the other arrays (a zoomed camera may see one marker per array
    and tens over the projection), and every observation the outlier filter left out."""
    figure = Figure(figsize=PANEL_SIZE)
    axes = figure.subplots()
    height, width = thumbnail.shape[:2]
    size = view.image_size() or (width / scale, height / scale)
    axes.imshow(thumbnail, cmap="gray", vmin=0, vmax=255, extent=(-0.5, size[0] - 0.5, size[1] - 0.5, -0.5),
                interpolation="antialiased")
    shown = view.observed_arrays == array if array is not None else np.zeros(len(view.observed_px), dtype=bool)
    detected, elsewhere = view.observed_px[shown], view.observed_px[~shown]
    axes.scatter(elsewhere[:, 0], elsewhere[:, 1], s=8, c="#f1c40f", linewidths=0,
                 label=f"detected in the other arrays ({len(elsewhere)})")
    axes.scatter(detected[:, 0], detected[:, 1], s=30, facecolors="none", edgecolors="#2ecc71", linewidths=0.9,
                 label=f"detected in this array ({len(detected)})")
    reprojected = view.projected_px[view.residual_arrays == array] if array is not None else np.zeros((0, 2))
    axes.scatter(reprojected[:, 0], reprojected[:, 1], s=30, marker="+", c="#ff33cc", linewidths=0.9,
                 label=f"reprojected ({len(reprojected)})")
    outliers = view.residual_at_px[view.outliers]
    axes.scatter(outliers[:, 0], outliers[:, 1], s=30, marker="x", c=FAILED_COLOUR, linewidths=1.2,
                 label=f"left out, all arrays ({len(outliers)})")
    _image_frame(axes, view)
    axes.set_xlim(-0.5, size[0] - 0.5)
    axes.set_ylim(size[1] - 0.5, -0.5)
    which = f"array {array}" if array is not None else "no array known"
    axes.set_title(f"a frame of the video ({which})", fontsize=10)
    axes.legend(fontsize=7, loc="lower right", framealpha=0.8)
    figure.tight_layout()
    return png_bytes(figure, dpi)


def _empty(axes, message: str) -> None:
    axes.text(0.5, 0.5, message, ha="center", va="center", transform=axes.transAxes)
    axes.set_axis_off()


def _histogram(axes, errors: np.ndarray, metrics) -> None:
    limit = max(float(np.percentile(errors, 99.0)), 3.0 * float(np.mean(errors)), 1e-3)
    shown = errors[errors <= limit]
    axes.hist(shown, bins=40, range=(0.0, limit), color="#2b7bba")
    mean = float(np.mean(errors))
    axes.axvline(mean, color="black", linewidth=1, label=f"mean of all {mean:.3f} px")
    if metrics is not None and metrics.mean_px is not None:
        axes.axvline(metrics.mean_px, color="#e67e22", linewidth=1, linestyle="--",
                     label=f"mean of inliers {metrics.mean_px:.3f} px")
    hidden = len(errors) - len(shown)
    title = f"reprojection error, {len(errors)} observations"
    axes.set_title(title + (f"\n({hidden} beyond {limit:.2f} px not shown)" if hidden else ""), fontsize=10)
    axes.set_xlabel("error [px]")
    axes.set_ylabel("observations")
    axes.set_ylim(0.0, 1.3 * axes.get_ylim()[1])  # room for the legend above the bars
    axes.legend(fontsize=8, loc="upper right")


def _image_frame(axes, view: CameraView) -> None:
    size = view.image_size()
    if size is not None:
        width, height = size
        axes.set_xlim(-0.5, width - 0.5)
        axes.set_ylim(height - 0.5, -0.5)  # y down, as the image
    axes.set_aspect("equal")
    axes.set_xlabel("x [px]")
    axes.set_ylabel("y [px]")


def _residual_map(figure: Figure, axes, view: CameraView) -> None:
    """Each observation as a dot coloured by its error, and the mean residual of each
    coverage cell as an arrow: noise averages out in the arrows, a systematic error
    (a wrong distortion model, a bad pose) shows as a pattern."""
    errors = view.errors
    clip = max(float(np.percentile(errors, 99.0)), 1e-6)
    x, y = view.residual_at_px.T
    dots = axes.scatter(x, y, s=2, c=np.minimum(errors, clip), cmap="viridis", vmin=0.0, vmax=clip)
    colourbar = figure.colorbar(dots, ax=axes, fraction=0.046, pad=0.02)
    colourbar.set_label("error [px]")
    size = view.image_size() or (float(np.ptp(x)) + 1.0, float(np.ptp(y)) + 1.0)
    centres, means = _cell_means(view.residual_at_px, view.residuals, size, ARROW_CELLS)
    # An arrow as long as the camera's mean error spans a cell: pure noise, which
    # averages out over a cell, leaves short arrows; a systematic error does not.
    unit = float(np.mean(errors))
    if len(means) and unit > 0:
        magnify = 0.8 * max(size) / ARROW_CELLS / unit
        axes.quiver(centres[:, 0], centres[:, 1], magnify * means[:, 0], magnify * means[:, 1], color="#d62728",
                    angles="xy", scale_units="xy", scale=1.0, width=0.004)
        note = f"arrows: cell means, 1 cell long = {unit:.2f} px"
    else:
        note = f"no cell with {MIN_CELL_OBSERVATIONS} observations"
    _image_frame(axes, view)
    axes.set_title(f"error over the image\n{note}", fontsize=10)


def _cell_means(at: np.ndarray, residuals: np.ndarray, size: tuple[float, float],
                cells: int) -> tuple[np.ndarray, np.ndarray]:
    """Centres of the cells of a grid over the image holding observations, and the mean residual in each."""
    width, height = size
    step = max(width, height) / cells
    column = np.clip(((at[:, 0] + 0.5) // step).astype(int), 0, int(np.ceil(width / step)) - 1)
    row = np.clip(((at[:, 1] + 0.5) // step).astype(int), 0, int(np.ceil(height / step)) - 1)
    keys, inverse, counts = np.unique(np.column_stack([column, row]), axis=0, return_inverse=True,
                                      return_counts=True)
    inverse = inverse.ravel()
    sums = np.zeros((len(keys), 2))
    np.add.at(sums, inverse, residuals)
    enough = counts >= MIN_CELL_OBSERVATIONS
    centres = (keys[enough] + 0.5) * step - 0.5
    return centres, sums[enough] / counts[enough, None]


def _coverage(figure: Figure, axes, view: CameraView) -> None:
    size = view.image_size()
    points = view.observed_px
    if size is None:
        axes.text(0.5, 0.5, "no intrinsics", ha="center", va="center", transform=axes.transAxes)
        axes.set_axis_off()
        return
    width, height = size
    cells_x = COVERAGE_CELLS if width >= height else max(1, round(COVERAGE_CELLS * width / height))
    cells_y = COVERAGE_CELLS if height > width else max(1, round(COVERAGE_CELLS * height / width))
    counts, _, _ = np.histogram2d(points[:, 0], points[:, 1], bins=(cells_x, cells_y),
                                  range=((-0.5, width - 0.5), (-0.5, height - 0.5)))
    # vmax at least 1: a camera without observations is drawn empty, not saturated.
    image = axes.imshow(counts.T, extent=(-0.5, width - 0.5, height - 0.5, -0.5), cmap="Greens",
                        interpolation="nearest", vmin=0, vmax=max(1.0, float(counts.max())))
    if len(points):
        axes.scatter(points[:, 0], points[:, 1], s=0.2, c="#222222", alpha=0.3, linewidths=0)
    colourbar = figure.colorbar(image, ax=axes, fraction=0.046, pad=0.02)
    colourbar.set_label("observations per cell")
    _image_frame(axes, view)
    covered = 100.0 * np.count_nonzero(counts) / counts.size
    axes.set_title(f"coverage: {len(points)} observations\nin {covered:.0f} % of {cells_x}x{cells_y} cells",
                   fontsize=10)
