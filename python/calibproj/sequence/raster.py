"""Drawing marker cells by exact area coverage.

A pixel's value is the area-weighted mean of what covers it, with pixel ``(i, j)``
spanning ``[i - 0.5, i + 0.5] x [j - 0.5, j + 0.5]`` (OpenCV's convention: the centre
of the top-left pixel is (0, 0)). Edges that fall on pixel boundaries stay crisp, and
a marker's centre is exactly where it is asked to be for any (non-integer) module
size. Each cell is an axis-aligned rectangle, so the coverage is separable and one
marker is two small matrix products.
"""

from __future__ import annotations

import math

import numpy as np


def coverage_matrix(edges: np.ndarray, size: int) -> tuple[int, np.ndarray]:
    """Fraction of pixels covered by consecutive intervals along one image axis.

    Args:
        edges: increasing interval boundaries ``(n + 1,)`` in pixel coordinates.
        size: number of pixels along the axis.

    Returns:
        ``(first, W)``: the first pixel touched and ``W`` of shape ``(pixels, n)`` with
        ``W[p, k]`` the part of pixel ``first + p`` inside interval ``k``. Pixels
        outside ``[0, size)`` are cut off.
    """
    first = max(0, math.floor(edges[0] + 0.5))
    last = min(size, math.ceil(edges[-1] + 0.5))
    if last <= first:
        return first, np.zeros((0, len(edges) - 1))
    pixels = np.arange(first, last, dtype=np.float64)[:, None]
    left = np.maximum(edges[None, :-1], pixels - 0.5)
    right = np.minimum(edges[None, 1:], pixels + 0.5)
    return first, np.clip(right - left, 0.0, None)


def draw_cells(canvas: np.ndarray, cells: np.ndarray, centre: tuple[float, float], side: float) -> None:
    """Paint a square grid of cells onto ``canvas`` in place.

    Args:
        canvas: float image ``(H, W)``, values in [0, 1].
        cells: ``(n, n)`` cell values in [0, 1], row 0 at the top.
        centre: ``(x, y)`` of the grid's centre in pixels.
        side: side of the whole grid in pixels.
    """
    n_rows, n_cols = cells.shape
    height, width = canvas.shape
    offsets_x = (np.arange(n_cols + 1) / n_cols - 0.5) * side
    offsets_y = (np.arange(n_rows + 1) / n_rows - 0.5) * side
    x0, weights_x = coverage_matrix(centre[0] + offsets_x, width)
    y0, weights_y = coverage_matrix(centre[1] + offsets_y, height)
    if weights_x.size == 0 or weights_y.size == 0:
        return
    painted = weights_y @ cells @ weights_x.T
    covered = np.outer(weights_y.sum(axis=1), weights_x.sum(axis=1))
    region = canvas[y0 : y0 + weights_y.shape[0], x0 : x0 + weights_x.shape[0]]
    region *= 1.0 - covered
    region += painted
