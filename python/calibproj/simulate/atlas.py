"""A projector image and its Gaussian pyramid packed side by side in one float image.

Camera pixels far from the floor cover several projector pixels; sampling the
projector image at one point per camera pixel would alias (markers' edges would
jump by whole camera pixels). Each camera pixel therefore samples the pyramid level
whose blur matches its footprint (see ``calibproj.simulate.warp``). Packing every
level into one atlas lets one ``cv2.remap`` read any level at any pixel.

Coordinates follow OpenCV's convention (the centre of the top-left pixel is (0, 0)).
Level 0 is the projector image inside a black border of ``pad`` pixels; level ``l``
is ``cv2.pyrDown`` of level ``l - 1``, whose pixel ``i`` is centred on pixel ``2 i``
of the level below, so a projector coordinate ``x`` is ``(x + pad) / 2**l`` in level
``l``. The border is wide enough that every level keeps black pixels around the
image, which is what the projector throws outside its image.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Black pixels that every level keeps around the image: more than the reach of
# pyrDown's 5-tap kernel accumulated over the levels, plus one for bilinear reads.
BORDER_AT_DEEPEST_LEVEL = 8
# Black gap between levels in the atlas.
LEVEL_GAP = 2


@dataclass(frozen=True)
class AtlasLayout:
    """Where every pyramid level of a projector image sits in the atlas.

    Attributes:
        projector: projector resolution ``(width, height)``.
        levels: number of levels (level 0 is full resolution).
        pad: black border around level 0, pixels.
        origins: top-left ``(x, y)`` of every level in the atlas.
        sizes: ``(width, height)`` of every level, border included.
        shape: ``(height, width)`` of the atlas.
    """

    projector: tuple[int, int]
    levels: int
    pad: int
    origins: tuple[tuple[int, int], ...]
    sizes: tuple[tuple[int, int], ...]
    shape: tuple[int, int]

    @classmethod
    def for_projector(cls, projector: tuple[int, int], levels: int) -> AtlasLayout:
        """Level 0 on the left, the smaller levels stacked top to bottom on its right."""
        if levels < 1:
            raise ValueError(f"an atlas needs at least one level, got {levels}")
        pad = BORDER_AT_DEEPEST_LEVEL * 2 ** (levels - 1)
        sizes = [(projector[0] + 2 * pad, projector[1] + 2 * pad)]
        for _ in range(1, levels):
            width, height = sizes[-1]
            sizes.append(((width + 1) // 2, (height + 1) // 2))
        origins = [(0, 0)]
        column_x = sizes[0][0] + LEVEL_GAP
        y = 0
        for width, height in sizes[1:]:
            origins.append((column_x, y))
            y += height + LEVEL_GAP
        width = column_x + (sizes[1][0] if levels > 1 else 0)
        height = max(sizes[0][1], y)
        return cls(tuple(projector), levels, pad, tuple(origins), tuple(sizes), (height, width))

    def build(self, image: np.ndarray) -> np.ndarray:
        """The atlas (``float32``, values in [0, 1]) of a ``uint8`` projector image."""
        import cv2

        width, height = self.projector
        if image.shape != (height, width):
            raise ValueError(f"projector image of shape {image.shape}, expected {(height, width)}")
        atlas = np.zeros(self.shape, dtype=np.float32)
        level = np.zeros((self.sizes[0][1], self.sizes[0][0]), dtype=np.float32)
        level[self.pad:self.pad + height, self.pad:self.pad + width] = image
        level *= 1.0 / 255.0
        for index in range(self.levels):
            if index > 0:
                level = cv2.pyrDown(level)
            x, y = self.origins[index]
            atlas[y:y + level.shape[0], x:x + level.shape[1]] = level
        return atlas

    def atlas_coordinates(self, level: int, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Atlas coordinates of projector coordinates ``(x, y)`` read from ``level``.

        Points beyond the level's border are clamped onto it (black), so that no read
        strays into another level.
        """
        scale = 2.0 ** -level
        origin_x, origin_y = self.origins[level]
        width, height = self.sizes[level]
        level_x = np.clip((x + self.pad) * scale, 0.0, width - 2.0)
        level_y = np.clip((y + self.pad) * scale, 0.0, height - 2.0)
        return level_x + origin_x, level_y + origin_y


def level_variance(level: float | np.ndarray) -> float | np.ndarray:
    """Variance (projector pixels squared, per axis) of the blur that reading ``level``
    with bilinear interpolation applies to the projector image.

    pyrDown's kernel [1 4 6 4 1] / 16 has variance 1 at the scale of its input, so
    level ``l`` carries ``(4**l - 1) / 3``; bilinear interpolation between its pixels,
    ``2**l`` apart, adds ``4**l / 6``.
    """
    power = 4.0 ** np.asarray(level, dtype=np.float64)
    return power / 2.0 - 1.0 / 3.0
