"""The reflectance (albedo) of a textured floor as each camera pixel sees it.

A tiled floor (``FloorTexture``): square tiles whose albedo varies a little from tile
to tile, darker grout lines along the tile edges and round stains with soft edges.
Thin grout lines are not point-sampled (a far camera's pixel covers several
millimetres of floor): each line is a Gaussian dip whose width is at least the
pixel's footprint and whose depth keeps the light the line absorbs, as a pixel
integrating over it would see it.
"""

from __future__ import annotations

import numpy as np

from calibproj.simulate.scene import FloorTexture


def floor_albedo(texture: FloorTexture, floor_x: np.ndarray, floor_y: np.ndarray,
                 footprint_m: np.ndarray) -> np.ndarray:
    """Albedo (``float32``, 1 = plain floor) at floor points ``(floor_x, floor_y)`` seen
    by pixels covering ``footprint_m`` metres of floor; 1 where the points are NaN."""
    rng = np.random.default_rng(texture.seed)
    x = np.nan_to_num(floor_x, nan=0.0)
    y = np.nan_to_num(floor_y, nan=0.0)
    albedo = _tiles(texture, x, y, rng)
    albedo *= _grout(texture, x, footprint_m) * _grout(texture, y, footprint_m)
    albedo *= _stains(texture, x, y, rng)
    albedo[~(np.isfinite(floor_x) & np.isfinite(floor_y))] = 1.0
    return albedo.astype(np.float32)


def _tiles(texture: FloorTexture, x: np.ndarray, y: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Per-tile albedo around 1 (a table of 64 x 64 tiles, wrapped)."""
    table = 1.0 + texture.tile_albedo_std * rng.standard_normal((64, 64))
    column = np.floor(x / texture.tile_m).astype(np.int64) % 64
    row = np.floor(y / texture.tile_m).astype(np.int64) % 64
    return np.clip(table[row, column], 0.0, None)


def _grout(texture: FloorTexture, coordinate: np.ndarray, footprint_m: np.ndarray) -> np.ndarray:
    """Grout lines along one axis: 1 on the tiles, dipping towards ``grout_albedo``."""
    distance = np.abs(coordinate - texture.tile_m * np.round(coordinate / texture.tile_m))
    # A box of width grout_m as a Gaussian of the same variance, widened to the footprint;
    # the dip's area (light absorbed) stays that of the box.
    sigma = np.sqrt(texture.grout_m**2 / 12.0 + np.nan_to_num(footprint_m, nan=0.0) ** 2 / 12.0)
    area = (1.0 - texture.grout_albedo) * texture.grout_m
    depth = np.minimum(area / (sigma * np.sqrt(2.0 * np.pi)), 1.0 - texture.grout_albedo)
    return 1.0 - depth * np.exp(-0.5 * (distance / sigma) ** 2)


def _stains(texture: FloorTexture, x: np.ndarray, y: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Round stains at random over a 6 x 6 m area around the origin."""
    albedo = np.ones_like(x)
    for _ in range(texture.stains):
        cx, cy = rng.uniform(-3.0, 3.0, 2)
        radius = rng.uniform(0.2, 1.0) * texture.stain_radius_m
        darkness = rng.uniform(0.3, 1.0) * (1.0 - texture.stain_albedo)
        near = (np.abs(x - cx) < 3 * radius) & (np.abs(y - cy) < 3 * radius)
        if near.any():
            squared = ((x[near] - cx) ** 2 + (y[near] - cy) ** 2) / radius**2
            # A flat core with a soft edge (a raised-cosine-like profile).
            albedo[near] *= 1.0 - darkness / (1.0 + squared**3)
    return albedo
