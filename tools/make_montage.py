"""Montage of one projected pattern as every camera of a simulated room sees it.

Renders one still per camera with calibproj.simulate.render.render_stills (lens,
photometry and noise as in the simulated videos), shrinks each to a tile, labels
it with the camera's name, focal length and frame rate, and writes a grid as PNG.

    PYTHONPATH=python python3 tools/make_montage.py --scene or-full --out docs/or_full_montage.png
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

DEFAULT_PATTERN = 2  # array 0 at scale 2 in the default sequence: seen by the far and the zoomed cameras
DEFAULT_TILE_WIDTH = 480
DEFAULT_COLUMNS = 3


def parse_arguments(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", default="or-full", help="preset name or scene.json (default %(default)s)")
    parser.add_argument("--sequence", metavar="FILE",
                        help="sequence.json (default: the default sequence of calibproj generate)")
    parser.add_argument("--pattern", type=int, default=DEFAULT_PATTERN,
                        help="pattern index in the sequence (default %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="noise seed (default %(default)s)")
    parser.add_argument("--tile-width", type=int, default=DEFAULT_TILE_WIDTH,
                        help="width of one camera's tile, pixels (default %(default)s)")
    parser.add_argument("--columns", type=int, default=DEFAULT_COLUMNS, help="tiles per row (default %(default)s)")
    parser.add_argument("--out", required=True, type=Path, help="PNG file to write")
    return parser.parse_args(argv)


def label_tile(image, text: str):
    import cv2

    cv2.rectangle(image, (0, 0), (image.shape[1] - 1, 22), 0, thickness=-1)
    cv2.putText(image, text, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, 255, 1, cv2.LINE_AA)
    return image


def montage(tiles: list, columns: int):
    import numpy as np

    rows = math.ceil(len(tiles) / columns)
    height, width = tiles[0].shape
    sheet = np.zeros((rows * height, columns * width), dtype=np.uint8)
    for index, tile in enumerate(tiles):
        row, column = divmod(index, columns)
        sheet[row * height:(row + 1) * height, column * width:(column + 1) * width] = tile
    return sheet


def main(argv: list[str] | None = None) -> int:
    args = parse_arguments(argv)
    import cv2

    from calibproj.sequence.builder import build_sequence
    from calibproj.simulate.render import render_stills
    from calibproj.simulate.scene import load_scene

    scene = load_scene(args.scene, seed=args.seed)
    sequence = args.sequence or build_sequence(projector=scene.projector.resolution)
    stills = render_stills(scene, sequence, args.pattern, seed=args.seed)
    tiles = []
    for camera in scene.cameras:
        image = stills[camera.name]
        height = round(image.shape[0] * args.tile_width / image.shape[1])
        tile = cv2.resize(image, (args.tile_width, height), interpolation=cv2.INTER_AREA)
        tiles.append(label_tile(tile, f"{camera.name}  fx {camera.fx:.0f}  {camera.fps:g} fps"))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(args.out), montage(tiles, args.columns), [cv2.IMWRITE_PNG_COMPRESSION, 9]):
        raise RuntimeError(f"{args.out}: could not write the PNG")
    print(f"{args.out}: {len(tiles)} cameras, pattern {args.pattern}, {args.out.stat().st_size / 1e3:.0f} kB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
