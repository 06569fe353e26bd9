"""Where the MSMs of every array sit in the projector image.

The union of all arrays is one dense regular grid of centres. Array ``a`` takes
every ``nx``-th column and every ``ny``-th row of that grid, shifted by its own
sub-cell offset, so markers of one array are ``nx`` (resp. ``ny``) grid steps
apart and never overlap while all arrays together cover the grid densely.
The grid spans the projector image minus a margin that keeps the largest scale
of every marker inside the image.

Centres are snapped (by at most half a pixel) so that the edges of a marker at scale
1 fall on pixel boundaries: with an even side in pixels, on half-integer coordinates
(OpenCV's convention puts pixel centres on integers). Every scale with an integer
module size then has crisp edges too; the others are drawn by exact area coverage
around the same centre (see ``calibproj.sequence.raster``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MsmLayout:
    """Geometry of the MSM arrays in projector pixels.

    Attributes:
        projector: projector resolution ``(width, height)`` in pixels.
        grid: markers per array as ``(rows, cols)``; the paper uses 4x8.
        arrays: number of arrays (each at its own sub-cell offset).
        scales: scale factors of every MSM; the paper uses 1, 1.4, 2, 3, 4, 6, 8.
        marker_px: side of a marker at scale 1 in projector pixels, border included.
        margin_px: distance from the image edge to the outermost centres; ``None``
            keeps the largest scale inside the image with one quiet module to spare.
        snap_to_pixels: move every centre by at most half a pixel so that marker
            edges at scale 1 fall on pixel boundaries (crisp projected edges).
    """

    projector: tuple[int, int] = (1920, 1080)
    grid: tuple[int, int] = (4, 8)
    arrays: int = 100
    scales: tuple[float, ...] = (1.0, 1.4, 2.0, 3.0, 4.0, 6.0, 8.0)
    marker_px: float = 24.0
    margin_px: float | None = None
    snap_to_pixels: bool = True

    def __post_init__(self) -> None:
        width, height = self.projector
        rows, cols = self.grid
        if width <= 0 or height <= 0:
            raise ValueError(f"projector resolution must be positive, got {width}x{height}")
        if rows <= 0 or cols <= 0:
            raise ValueError(f"grid must be at least 1x1, got {rows}x{cols}")
        if self.arrays <= 0:
            raise ValueError(f"number of arrays must be at least 1, got {self.arrays}")
        if not self.scales or min(self.scales) <= 0:
            raise ValueError(f"scales must be positive, got {list(self.scales)}")
        if self.marker_px <= 0:
            raise ValueError(f"marker size must be positive, got {self.marker_px} px")
        if self.span[0] <= 0 or self.span[1] <= 0:
            raise ValueError(
                f"grid {rows}x{cols} with margin {self.margin:.1f} px does not fit a "
                f"{width}x{height} projector"
            )

    @property
    def markers_per_array(self) -> int:
        return self.grid[0] * self.grid[1]

    @property
    def margin(self) -> float:
        if self.margin_px is not None:
            return float(self.margin_px)
        largest = self.marker_px * max(self.scales)
        return 0.5 * largest + largest / 6.0

    @property
    def span(self) -> tuple[float, float]:
        """Extent ``(width, height)`` of the dense grid of centres in projector pixels."""
        width, height = self.projector
        return (width - 2.0 * self.margin, height - 2.0 * self.margin)

    @property
    def offsets_shape(self) -> tuple[int, int]:
        """Sub-cell offsets per array cell as ``(ny, nx)``, ``ny * nx >= arrays``.

        Chosen so that the dense grid steps are as square as possible.
        """
        rows, cols = self.grid
        cell_w = self.span[0] / cols
        cell_h = self.span[1] / rows
        nx = max(1, round(math.sqrt(self.arrays * cell_w / cell_h)))
        ny = math.ceil(self.arrays / nx)
        return ny, nx

    def centres(self) -> np.ndarray:
        """Marker centres in projector pixels, shape ``(arrays, rows * cols, 2)``.

        Marker ``m`` of an array is at grid row ``m // cols`` and column ``m % cols``.
        """
        rows, cols = self.grid
        ny, nx = self.offsets_shape
        dense_cols, dense_rows = cols * nx, rows * ny
        step_x = self.span[0] / max(dense_cols - 1, 1)
        step_y = self.span[1] / max(dense_rows - 1, 1)
        out = np.empty((self.arrays, rows * cols, 2))
        marker_row, marker_col = np.divmod(np.arange(rows * cols), cols)
        for array in range(self.arrays):
            oy, ox = divmod(array, nx)
            out[array, :, 0] = self.margin + (marker_col * nx + ox) * step_x
            out[array, :, 1] = self.margin + (marker_row * ny + oy) * step_y
        return snap_centres(out, self.marker_px) if self.snap_to_pixels else out

    def marker_side(self, scale: float) -> float:
        """Side of a marker at ``scale`` in projector pixels, border included."""
        return self.marker_px * scale

    def outside_image(self, side: float) -> np.ndarray:
        """``(arrays, markers)``: whether a marker of ``side`` pixels would leave the image.

        The image covers ``[-0.5, width - 0.5] x [-0.5, height - 0.5]`` (pixel centres
        on integers).
        """
        return outside_image(self.centres(), side, self.projector)

    def too_close(self, side: float, gap: float) -> np.ndarray:
        """``(arrays, markers, markers)``: pairs of markers of one array closer than ``gap``.

        Two squares of ``side`` pixels (axis-aligned) leave less than ``gap`` pixels
        between them when both centre distances are under ``side + gap``.
        """
        centres = self.centres()
        distance = np.abs(centres[:, :, None, :] - centres[:, None, :, :])
        close = (distance < side + gap - 1e-9).all(axis=-1)
        close[:, np.arange(self.markers_per_array), np.arange(self.markers_per_array)] = False
        return close

    def marker_pitch(self) -> tuple[float, float]:
        """Distance between neighbouring markers of one array ``(dx, dy)`` in pixels."""
        rows, cols = self.grid
        ny, nx = self.offsets_shape
        dx = self.span[0] / max(cols * nx - 1, 1) * nx
        dy = self.span[1] / max(rows * ny - 1, 1) * ny
        return dx, dy


def outside_image(centres: np.ndarray, side: float, projector: tuple[int, int]) -> np.ndarray:
    """Whether squares of ``side`` pixels at ``centres`` (``(..., 2)``) leave a projector
    image of ``projector = (width, height)`` pixels (pixel centres on integers)."""
    limits = np.asarray(projector, dtype=np.float64) - 0.5
    low = np.asarray(centres, dtype=np.float64) - 0.5 * side
    high = np.asarray(centres, dtype=np.float64) + 0.5 * side
    return ((low < -0.5 - 1e-9) | (high > limits + 1e-9)).any(axis=-1)


def snap_centres(centres: np.ndarray, marker_px: float) -> np.ndarray:
    """Centres moved by at most half a pixel so that a marker of ``marker_px`` pixels has
    its left edge (centre - side / 2) on a pixel boundary, i.e. on k + 0.5."""
    half_side = 0.5 * marker_px
    return np.round(np.asarray(centres, dtype=np.float64) - half_side - 0.5) + 0.5 + half_side
