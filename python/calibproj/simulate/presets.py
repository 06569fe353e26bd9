"""Built-in scenes, as scene documents (the JSON of ``scene.json``).

- ``paper``: the synthetic rig of the paper (section 3.1): 6 cameras on a circle of
  radius 2.8 m at height 2.8 m and 4 on a circle of radius 1.2 m at height 1.4 m, all
  looking at the floor centre, fx = 917, 1920x1080, no distortion. As in the paper,
  every simulation draws the cameras' angles on their circles at random (from the seed).
- ``or-full``: the mock operating room of the paper (section 3.2): 6 far-field
  GoPro-like cameras (fx ~915, wide-angle distortion) high on the walls, 2 near-field
  GoPros on surgical lamps, 1 ceiling camera zoomed on the table (fx 11,100), all
  1920x1080, at different frame rates and start times.
- ``easy``, ``medium``, ``hard``: subsets and variants of ``or-full`` in the spirit of
  the paper's setups: five GoPros with wide overlap; fewer far-field cameras plus the
  lamps and the zoomed camera; and two far-field cameras (one low, seeing the floor at
  a grazing angle), one lamp turned away from the table and the zoomed camera.
- ``small``: 3 cameras at 640x360 for fast rendered tests.
- ``demo``: the room of ``calibproj demo``: 4 far-field GoPros, 1 on a lamp and 1
  zoomed on the table (fx 7,400), all 1280x720, so that a whole calibration from
  rendered videos takes a few minutes on 2 cores.
- ``or-real``: the demo room as real cameras and a real room record it: 2 % dropped
  frames and 1 ms timing jitter, 15 ms rolling shutters, automatic exposure on two
  cameras, harder compression on two, a tiled floor with stains, some room light.
- ``live``: the room of the virtual operating room (``calibproj demo --live``): the
  demo's geometry at 640x360 under a 960x540 projector, four cameras (one zoomed).
- ``or-table``: the demo room with its operating table left in place (top at 0.9 m on
  a column) and an instrument cart: the projection lands on them too, they shade the
  floor behind them from the projector and hide parts of it from the cameras.

The projector of every preset but ``live`` hangs at 3 m looking straight down; with fx 1400 its
1920x1080 image covers about 4.1 x 2.3 m of floor, so a marker of 24 projector pixels
(scale 1 of the default layout) is 5 cm wide and one at scale 8 is 40 cm, as in the paper.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from typing import Any

import numpy as np

HD = [1920, 1080]
PROJECTOR = {"position": [0.0, 0.0, 3.0], "look_at": [0.0, 0.0, 0.0], "resolution": HD, "fx": 1400.0}

# A GoPro-like wide-angle lens at 1920x1080 (barrel distortion, one-to-one over the image).
GOPRO_DIST = [-0.26, 0.09, 0.0003, -0.0002, -0.012]

PAPER_FX = 917.0
PAPER_FAR = {"count": 6, "radius_m": 2.8, "height_m": 2.8}
PAPER_NEAR = {"count": 4, "radius_m": 1.2, "height_m": 1.4}


def _gopro(name: str, position: list[float], look_at: list[float], fx: float, fps: float,
           start_offset_s: float, dist_scale: float = 1.0, centre_shift: tuple[float, float] = (0.0, 0.0)) -> dict:
    """A GoPro-like camera; small per-unit differences make the intrinsics realistic."""
    return {
        "name": name, "position": position, "look_at": look_at, "resolution": HD,
        "fx": fx, "fy": round(fx * 1.0006, 2), "cx": 959.5 + centre_shift[0], "cy": 539.5 + centre_shift[1],
        "dist": [round(c * dist_scale, 6) for c in GOPRO_DIST],
        "fps": fps, "start_offset_s": start_offset_s, "exposure_s": round(min(0.01, 0.5 / fps), 5),
    }


def _or_cameras() -> list[dict]:
    """The nine cameras of the mock operating room (table centre at the floor origin).

    The far-field cameras stand 3.6-3.9 m from the table, so that the mean distance
    between the nine cameras is 4.2 m, as in the paper's room (4.22 m).
    """
    return [
        _gopro("far1", [3.6, 0.4, 2.7], [0.2, 0.0, 0.0], 915.0, 30.0, 0.0, 1.00, (3.1, -2.4)),
        _gopro("far2", [2.0, 3.0, 2.8], [0.0, 0.0, 0.0], 913.4, 29.97, 1.37, 0.97, (-4.2, 1.8)),
        _gopro("far3", [-1.5, 3.1, 2.6], [0.0, -0.2, 0.0], 916.8, 25.0, 2.81, 1.03, (1.7, 3.3)),
        _gopro("far4", [-3.6, 0.5, 2.75], [0.0, 0.0, 0.0], 914.1, 50.0, 0.52, 0.99, (-2.6, -1.1)),
        _gopro("far5", [-2.25, -2.9, 2.7], [0.1, 0.1, 0.0], 917.5, 60.0, 3.9, 1.02, (0.8, 2.2)),
        _gopro("far6", [1.6, -3.1, 2.85], [0.0, 0.2, 0.0], 915.9, 30.0, 0.18, 0.98, (-1.5, -3.0)),
        _gopro("near1", [0.7, 0.5, 2.0], [0.0, -0.1, 0.0], 914.6, 29.97, 1.05, 1.01, (2.4, 0.6)),
        _gopro("near2", [-0.6, -0.6, 1.85], [0.1, 0.1, 0.0], 916.2, 60.0, 2.26, 0.99, (-0.9, -2.7)),
        {
            # A ceiling PTZ camera with a strong optical zoom on the table: ~0.5 x 0.3 m of floor.
            "name": "ceiling", "position": [0.9, 0.6, 2.95], "look_at": [0.05, 0.0, 0.0], "resolution": HD,
            "fx": 11100.0, "fy": 11100.0, "cx": 963.2, "cy": 536.8, "dist": [-0.02, 0.0, 0.0, 0.0, 0.0],
            "fps": 25.0, "start_offset_s": 0.77, "exposure_s": 0.01,
        },
    ]


def _room(cameras: list[dict], floor_m: tuple[float, float] = (8.0, 7.0)) -> dict[str, Any]:
    return {
        "schema": "calibproj.scene/1",
        "floor": {"size_m": list(floor_m)},
        "projector": copy.deepcopy(PROJECTOR),
        "cameras": cameras,
    }


def _pick(names: list[str]) -> list[dict]:
    by_name = {camera["name"]: camera for camera in _or_cameras()}
    return [by_name[name] for name in names]


def or_full(rng: np.random.Generator) -> dict[str, Any]:
    return _room(_or_cameras())


def easy(rng: np.random.Generator) -> dict[str, Any]:
    return _room(_pick(["far1", "far2", "far4", "far5", "near1"]))


def medium(rng: np.random.Generator) -> dict[str, Any]:
    return _room(_pick(["far1", "far3", "far5", "near1", "near2", "ceiling"]))


def hard(rng: np.random.Generator) -> dict[str, Any]:
    cameras = _pick(["far2", "far5", "near2", "ceiling"])
    # far2 comes down to 0.9 m in the room's corner and looks level across the room, so
    # it sees the floor at a grazing angle in the distorted bottom of its image; near2's
    # lamp is turned away from the table and shares only a corner with the zoomed camera.
    cameras[0].update(position=[2.6, 2.4, 0.9], look_at=[-2.0, 1.5, 0.9])
    cameras[2].update(look_at=[0.9, -1.3, 0.0])
    return _room(cameras)


def small(rng: np.random.Generator) -> dict[str, Any]:
    def camera(name, position, fps, offset, dist):
        return {"name": name, "position": position, "look_at": [0.0, 0.0, 0.0], "resolution": [640, 360],
                "fx": 305.0, "fy": 305.0, "cx": 319.5, "cy": 179.5, "dist": dist,
                "fps": fps, "start_offset_s": offset, "exposure_s": 0.01}

    return _room([
        camera("cam1", [2.5, 0.5, 2.6], 30.0, 0.0, [0.0] * 5),
        camera("cam2", [-1.5, 2.0, 2.4], 25.0, 0.43, [-0.1, 0.02, 0.0, 0.0, 0.0]),
        camera("cam3", [-0.8, -2.2, 2.2], 29.97, 1.12, [0.0] * 5),
    ])


def paper(rng: np.random.Generator) -> dict[str, Any]:
    cameras = []
    for prefix, ring in (("far", PAPER_FAR), ("near", PAPER_NEAR)):
        angles = rng.uniform(0.0, 2.0 * math.pi, ring["count"])
        for index, angle in enumerate(angles, start=1):
            position = [ring["radius_m"] * math.cos(angle), ring["radius_m"] * math.sin(angle), ring["height_m"]]
            cameras.append({
                "name": f"{prefix}{index}", "position": [round(v, 9) for v in position],
                "look_at": [0.0, 0.0, 0.0], "resolution": HD, "fx": PAPER_FX,
            })
    return _room(cameras, floor_m=(6.0, 6.0))


# name -> builder(rng) of the scene document.
def demo(rng: np.random.Generator) -> dict[str, Any]:
    def at_720p(camera: dict) -> dict:
        scale = 1280.0 / 1920.0
        return {**camera, "resolution": [1280, 720], "fx": round(camera["fx"] * scale, 2),
                "fy": round(camera["fy"] * scale, 2), "cx": round((camera["cx"] + 0.5) * scale - 0.5, 3),
                "cy": round((camera["cy"] + 0.5) * scale - 0.5, 3)}

    return _room([at_720p(camera) for camera in _pick(["far1", "far2", "far4", "far5", "near1", "ceiling"])])


# What real cameras and a real room add, at typical levels (or-real): frame timing of
# phones and IP cameras, rolling shutters (at most 90 % of a frame), automatic
# exposure on the cameras that have no manual mode, harder compression on cheap
# ones, a tiled floor with stains, some room light, and two people crossing the
# projection while the patterns play.
REAL_PEOPLE = [{"start": [-2.5, -0.6], "end": [2.5, 0.9], "start_s": 5.0, "speed_mps": 0.8},
               {"start": [1.8, -2.0], "end": [-1.8, 2.0], "start_s": 9.0, "speed_mps": 0.6}]
REAL_TIMING = {"drop_rate": 0.02, "frame_jitter_s": 0.001}
REAL_READOUT_S = 0.015
REAL_AUTO_EXPOSURE = {"target": 0.45, "time_constant_s": 0.5, "min_gain": 0.25, "max_gain": 8.0}
REAL_AUTO_EXPOSURE_CAMERAS = ("far2", "near1")
REAL_CRF = {"far4": 26, "far5": 26}
REAL_FLOOR_TEXTURE = {"tile_m": 0.6, "grout_m": 0.006, "grout_albedo": 0.45, "tile_albedo_std": 0.04,
                      "stains": 25, "stain_radius_m": 0.12, "stain_albedo": 0.55, "seed": 0}
REAL_PHOTOMETRIC = {"ambient": 0.15, "contrast": 0.6}


def or_real(rng: np.random.Generator) -> dict[str, Any]:
    document = demo(rng)
    for camera in document["cameras"]:
        camera.update(REAL_TIMING)
        camera["readout_s"] = round(min(REAL_READOUT_S, 0.9 / camera["fps"]), 6)
        if camera["name"] in REAL_AUTO_EXPOSURE_CAMERAS:
            camera["auto_exposure"] = dict(REAL_AUTO_EXPOSURE)
        if camera["name"] in REAL_CRF:
            camera["crf"] = REAL_CRF[camera["name"]]
    document["floor"]["texture"] = dict(REAL_FLOOR_TEXTURE, seed=int(rng.integers(0, 2**31)))
    document["photometric"] = dict(REAL_PHOTOMETRIC)
    document["people"] = copy.deepcopy(REAL_PEOPLE)
    return document


# An operating table fixed on its column at the floor centre (top 2.0 x 0.55 m at
# 0.9 m), and an instrument cart beside it: they stay while the projection plays.
TABLE_BOXES = [
    {"centre": [0.0, 0.0], "size_m": [2.0, 0.55, 0.08], "bottom_m": 0.82, "albedo": 0.75},
    {"centre": [0.0, 0.0], "size_m": [0.35, 0.3, 0.82], "albedo": 0.5},
    {"centre": [1.3, -0.95], "size_m": [0.6, 0.45, 0.9], "albedo": 0.85},
]


def or_table(rng: np.random.Generator) -> dict[str, Any]:
    document = demo(rng)
    document["boxes"] = copy.deepcopy(TABLE_BOXES)
    return document


# The virtual operating room (``calibproj.simulate.virtual_room``): what 2 cores render,
# encode, stream and ingest live at once. The demo's geometry at a quarter of the
# pixels: a 960x540 projector (fx 700: the same 4.1 x 2.3 m of floor) and four 640x360
# cameras, two far-field, one on a lamp and the ceiling camera zoomed on the table (6x),
# each with its own frame rate, start, timing jitter and dropped frames.
LIVE_PROJECTOR = {"position": [0.0, 0.0, 3.0], "look_at": [0.0, 0.0, 0.0], "resolution": [960, 540], "fx": 700.0}
LIVE_TIMING = {"drop_rate": 0.01, "frame_jitter_s": 0.001}
LIVE_CEILING_FX = 1850.0


def live(rng: np.random.Generator) -> dict[str, Any]:
    def at_360p(camera: dict) -> dict:
        scale = 640.0 / 1920.0
        return {**camera, "resolution": [640, 360], "fx": round(camera["fx"] * scale, 2),
                "fy": round(camera["fy"] * scale, 2), "cx": round((camera["cx"] + 0.5) * scale - 0.5, 3),
                "cy": round((camera["cy"] + 0.5) * scale - 0.5, 3), **LIVE_TIMING}

    document = _room([at_360p(camera) for camera in _pick(["far1", "far4", "near1", "ceiling"])])
    document["projector"] = copy.deepcopy(LIVE_PROJECTOR)
    # Zoomed 6x over the far-field cameras onto about 1.0 x 0.55 m of the table: at the
    # demo's zoom its view would hold fewer whole markers of a 960-pixel projector than a
    # projection of seconds can place.
    document["cameras"][-1].update(fx=LIVE_CEILING_FX, fy=LIVE_CEILING_FX)
    return document


PRESETS: dict[str, Callable[[np.random.Generator], dict[str, Any]]] = {
    "paper": paper,
    "or-full": or_full,
    "easy": easy,
    "medium": medium,
    "hard": hard,
    "small": small,
    "demo": demo,
    "or-real": or_real,
    "or-table": or_table,
    "live": live,
}


def preset_document(name: str, seed: int | None = 0) -> dict[str, Any]:
    """The scene document of a preset; ``seed`` drives its random parts (``paper`` only)."""
    if name not in PRESETS:
        raise ValueError(f"unknown scene preset {name!r} (presets: {', '.join(PRESETS)})")
    return PRESETS[name](np.random.default_rng(seed))
