"""Simulated rooms: a floor, a ceiling projector and cameras, read from and written to ``scene.json``.

A scene is in metres, in the floor frame (z up, floor z = 0). Every device is placed
by its ``position`` and the point it looks at (``look_at``); its orientation follows
from those with the rule of ``look_at_rotation``: no roll, the image "up" is the
world +z direction, and a device looking straight down (or up) has the top of its
image towards world +y.

File format (``calibproj.scene/1``, see DESIGN.md)::

    {"schema": "calibproj.scene/1",
     "floor": {"size_m": [4.0, 3.0]},
     "projector": {"position": [0, 0, 3], "look_at": [0, 0, 0], "resolution": [1920, 1080], "fx": 1400},
     "cameras": [{"name": "far1", "position": [...], "look_at": [...], "resolution": [1920, 1080],
                  "fx": 915, "fy": 915, "cx": 960, "cy": 540, "dist": [k1, k2, p1, p2, k3],
                  "fps": 30, "start_offset_s": 0.37, "exposure_s": 0.01}, ...],
     "photometric": {"ambient": 0.05, "contrast": 0.8, "noise_std": 2.0,
                     "blur_px": 0.7, "vignetting": 0.3, "gamma": 2.2}}

``fy`` defaults to ``fx``; ``cx``, ``cy`` to the image centre ``((w - 1) / 2, (h - 1) / 2)``;
``dist`` to no distortion; ``fps`` to 30, ``start_offset_s`` to 0, ``exposure_s`` to
0.01 s (at most one frame); ``photometric`` to the defaults of ``Photometric``.

Frame timing of real cameras (optional, per camera): ``frame_jitter_s`` is the
standard deviation of each frame's exposure start around the frame grid (Gaussian,
clipped to 3 sigma; default 0), ``drop_rate`` the share of frames the camera drops
at random (default 0). Rendered videos carry the true exposure starts as their
container timestamps, so a dropped frame is a gap in the timestamps. ``readout_s``
is a rolling shutter's readout time (row ``y`` of ``h`` starts exposing
``readout_s * y / h`` after the first; default 0, a global shutter), and
``auto_exposure`` (``AutoExposure``'s fields) makes the camera adjust its gain, and
``crf`` is the camera's own x264 quality (cheap cameras compress harder; default:
the renderer's).
``floor.texture`` (``FloorTexture``'s fields) gives the floor tiles, grout and stains;
``floor.relief`` (``FloorRelief``'s fields: ``rms_m``, ``wavelength_m``, ``seed``)
makes it slightly uneven, its height a smooth surface around z = 0.
``people`` (a list of ``Person``'s fields: ``start`` and ``end`` on the floor, ``start_s``,
``speed_mps``, ``radius_m``, ``height_m``, ``albedo``) walk through the room during the
projection, hiding the floor and casting shadows.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from calibproj.formats.intrinsics import DISTORTION_LENGTHS, Intrinsics
from calibproj.formats.jsonio import FormatError, read_json, write_json
from calibproj.simulate.presets import PRESETS, preset_document

SCHEMA_KIND = "scene"
SCHEMA_MAJOR = 1

# Below this |sin| between the optical axis and the vertical a device counts as
# looking straight down (or up), and the image top is put towards world +y.
VERTICAL_AXIS_TOLERANCE = 1e-9

CAMERA_NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


def look_at_rotation(position: np.ndarray, target: np.ndarray) -> np.ndarray:
    """World-to-camera rotation of a device at ``position`` looking at ``target``.

    Rows are the camera axes in world coordinates (OpenCV: x right, y down, z forward).
    No roll: the image x axis is horizontal and the image "up" (-y) points towards
    world +z. Looking straight down or up, the horizon is undefined; the image top
    then points towards world +y (so a projector looking down maps image x to world x).
    """
    forward = np.asarray(target, dtype=float) - np.asarray(position, dtype=float)
    norm = np.linalg.norm(forward)
    if norm == 0.0:
        raise ValueError("position and look_at coincide")
    forward /= norm
    up = np.array([0.0, 0.0, 1.0])
    right = np.cross(forward, up)
    if np.linalg.norm(right) < VERTICAL_AXIS_TOLERANCE:
        right = np.cross(forward, np.array([0.0, 1.0, 0.0]))
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return np.stack([right, down, forward])


# Plane waves summed into a floor's relief, and fixed-point steps that meet it (each
# step shrinks the error by the slope times the run per drop: below 0.05 in a room).
RELIEF_WAVES = 8
RELIEF_ITERATIONS = 8


@dataclass(frozen=True)
class FloorTexture:
    """What a real floor adds to the projected light: tiles of slightly different
    albedo, darker grout lines between them and stains (the floor's reflectance
    multiplies the projector's light and the room light alike).

    Attributes:
        tile_m: side of the square tiles (metres; tile edges on multiples of it).
        grout_m: width of the grout lines.
        grout_albedo: reflectance of the grout (the tiles' is about 1).
        tile_albedo_std: spread of the tiles' reflectance from tile to tile.
        stains: stains on the floor (round, soft-edged), at random places.
        stain_radius_m: largest stain radius (radii drawn up to it).
        stain_albedo: reflectance at the centre of the darkest stain.
        seed: draws of the tiles and stains.
    """

    tile_m: float = 0.6
    grout_m: float = 0.006
    grout_albedo: float = 0.45
    tile_albedo_std: float = 0.04
    stains: int = 25
    stain_radius_m: float = 0.12
    stain_albedo: float = 0.55
    seed: int = 0


@dataclass(frozen=True)
class FloorRelief:
    """A floor that is not quite flat, as a poured or tiled floor is: its height is a
    smooth random surface, a sum of ``RELIEF_WAVES`` plane waves of random directions
    and phases whose wavelengths spread around ``wavelength_m``, with a root mean
    square height of ``rms_m`` (DIN 18202 allows 4 mm under a 1 m straightedge).

    Attributes:
        rms_m: root mean square height above and below z = 0 (metres).
        wavelength_m: typical distance between a high and the next high.
        seed: draws of the waves.
    """

    rms_m: float = 0.003
    wavelength_m: float = 1.5
    seed: int = 0

    def _waves(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Wave vectors ``(K, 2)`` (radians per metre), phases and amplitudes ``(K,)``."""
        rng = np.random.default_rng(self.seed)
        angles = rng.uniform(0.0, np.pi, RELIEF_WAVES)
        wavelengths = self.wavelength_m * rng.uniform(0.7, 1.3, RELIEF_WAVES)
        vectors = (2.0 * np.pi / wavelengths)[:, None] * np.column_stack([np.cos(angles), np.sin(angles)])
        phases = rng.uniform(0.0, 2.0 * np.pi, RELIEF_WAVES)
        # Each cosine's mean square is half its amplitude squared.
        amplitudes = np.full(RELIEF_WAVES, self.rms_m * np.sqrt(2.0 / RELIEF_WAVES))
        return vectors, phases, amplitudes

    def height(self, xy: np.ndarray) -> np.ndarray:
        """Height of the floor (metres) at floor points ``(N, 2)``; NaN stays NaN."""
        vectors, phases, amplitudes = self._waves()
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        return np.cos(xy @ vectors.T + phases) @ amplitudes


@dataclass(frozen=True)
class Floor:
    """The floor, a rectangle centred on the origin: the plane z = 0, or a smooth
    surface close to it when it has a relief; plain (albedo 1) unless it has a texture."""

    size_m: tuple[float, float] = (4.0, 3.0)
    texture: FloorTexture | None = None
    relief: FloorRelief | None = None

    def height(self, xy: np.ndarray) -> np.ndarray:
        """Height of the floor at floor points ``(N, 2)``: 0 where it is flat."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        return np.zeros(len(xy)) if self.relief is None else self.relief.height(xy)

    def ray_depths(self, origin: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Per ray from ``origin`` along ``directions`` ``(N, 3)``, the multiple of its
        direction at which it meets the floor; NaN for rays that never go down to it.

        A relief is met by fixed-point steps from the plane z = 0: each step moves the
        depth by the relief's slope times the ray's horizontal run per unit drop, a
        contraction for any ray not grazing the floor."""
        origin = np.asarray(origin, dtype=float)
        directions = np.asarray(directions, dtype=float).reshape(-1, 3)
        with np.errstate(divide="ignore", invalid="ignore"):
            depth = -origin[2] / directions[:, 2]
            depth[~(depth > 0)] = np.nan
            if self.relief is not None:
                for _ in range(RELIEF_ITERATIONS):
                    xy = origin[:2] + depth[:, None] * directions[:, :2]
                    depth = (self.relief.height(xy) - origin[2]) / directions[:, 2]
                depth[~(depth > 0)] = np.nan
        return depth


@dataclass(frozen=True)
class AutoExposure:
    """A camera that adjusts its gain to the scene (phones, webcams, IP cameras): after
    every frame the gain moves towards the one bringing the frame's mean grey level to
    ``target``, with a first-order lag, within limits (bright markers then saturate
    while the floor is mostly dark).

    Attributes:
        target: mean encoded grey level aimed at (full scale 1).
        time_constant_s: time constant of the adjustment.
        min_gain, max_gain: limits of the gain (irradiance factor).
        initial_gain: the gain of the first frame.
    """

    target: float = 0.45
    time_constant_s: float = 0.5
    min_gain: float = 0.25
    max_gain: float = 8.0
    initial_gain: float = 1.0


@dataclass(frozen=True)
class Person:
    """Someone walking through the room, a vertical cylinder: from ``start`` to ``end``
    (floor metres) at ``speed_mps``, setting off ``start_s`` after the projection starts
    and gone once there. Hides the floor behind from the cameras and casts a shadow in
    the projector's light (see ``calibproj.simulate.people``)."""

    start: tuple[float, float]
    end: tuple[float, float]
    start_s: float = 0.0
    speed_mps: float = 1.0
    radius_m: float = 0.25
    height_m: float = 1.7
    albedo: float = 0.4

    def __post_init__(self) -> None:
        # Points given as lists (as JSON gives them) compare equal to the tuples a scene file reads.
        object.__setattr__(self, "start", tuple(float(v) for v in self.start))
        object.__setattr__(self, "end", tuple(float(v) for v in self.end))

    def centre(self, time_s: float) -> np.ndarray | None:
        """Where the person stands at ``time_s`` (floor metres), None before or after."""
        start, end = np.asarray(self.start, dtype=float), np.asarray(self.end, dtype=float)
        length = float(np.linalg.norm(end - start))
        walked = (time_s - self.start_s) * self.speed_mps
        if walked < 0 or walked > length:
            return None
        return start if length == 0 else start + (end - start) * (walked / length)


@dataclass(frozen=True)
class Box:
    """Something that stays on the floor during the calibration: an axis-aligned box
    (an operating table's top or its column, a cart, a cabinet). It receives the
    projection on its top and sides, casts the projector's shadow on what is behind it
    and hides that from the cameras (``calibproj.simulate.boxes``).

    Attributes:
        centre: floor position of its vertical axis (metres).
        size_m: extent along x and y, and its height (metres).
        bottom_m: height of its underside (a table top stands on its column: 0.85).
        albedo: reflectance of its surfaces (the floor's is 1).
    """

    centre: tuple[float, float]
    size_m: tuple[float, float, float]
    bottom_m: float = 0.0
    albedo: float = 0.8

    @property
    def lower(self) -> np.ndarray:
        return np.array([self.centre[0] - self.size_m[0] / 2, self.centre[1] - self.size_m[1] / 2, self.bottom_m])

    @property
    def upper(self) -> np.ndarray:
        return np.array([self.centre[0] + self.size_m[0] / 2, self.centre[1] + self.size_m[1] / 2,
                         self.bottom_m + self.size_m[2]])


class LookAtPose:
    """World-to-device pose of a device placed at ``position`` looking at ``look_at``."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]

    @property
    def R(self) -> np.ndarray:
        return look_at_rotation(np.array(self.position), np.array(self.look_at))

    @property
    def t(self) -> np.ndarray:
        return -self.R @ np.array(self.position, dtype=float)

    @property
    def center(self) -> np.ndarray:
        return np.array(self.position, dtype=float)


@dataclass(frozen=True)
class Projector(LookAtPose):
    """A projector with its principal point at the image centre and, optionally, the
    radial distortion of its lens: ``dist = (k1, k2)`` in OpenCV's model (the pixel the
    frame buffer holds is the distorted image of the ray's ideal one)."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    resolution: tuple[int, int]
    fx: float
    dist: tuple[float, float] = (0.0, 0.0)

    @property
    def K(self) -> np.ndarray:
        width, height = self.resolution
        return np.array([[self.fx, 0.0, (width - 1) / 2.0], [0.0, self.fx, (height - 1) / 2.0], [0.0, 0.0, 1.0]])

    @property
    def lens(self) -> Intrinsics:
        return Intrinsics("projector", tuple(self.resolution), self.K, np.array([*self.dist, 0.0, 0.0, 0.0]))

    def ideal_pixels(self, pixels: np.ndarray) -> np.ndarray:
        """The pinhole pixels of the rays that frame-buffer pixels are thrown along."""
        pixels = np.asarray(pixels, dtype=float).reshape(-1, 2)
        return self.lens.undistort_points(pixels) if any(self.dist) else pixels

    def buffer_pixels(self, ideal: np.ndarray) -> np.ndarray:
        """The frame-buffer pixels thrown along the rays of pinhole pixels (NaN kept)."""
        ideal = np.asarray(ideal, dtype=float).reshape(-1, 2)
        if not any(self.dist):
            return ideal
        out = np.full_like(ideal, np.nan)
        finite = np.isfinite(ideal).all(axis=1)
        out[finite] = self.lens.distort_points(ideal[finite])
        return out

    def pixels_to_floor(self, pixels: np.ndarray, floor: Floor | None = None) -> np.ndarray:
        """Floor points, shape ``(N, 3)``, hit by the rays of projector pixels: on
        ``floor`` (its relief included), or on the plane z = 0 without one.

        Rays that do not go down towards the floor give NaN rows.
        """
        pixels = self.ideal_pixels(pixels)
        rays_cam = np.linalg.solve(self.K, np.column_stack([pixels, np.ones(len(pixels))]).T)
        rays_world = (self.R.T @ rays_cam).T
        depth = (floor or Floor()).ray_depths(self.center, rays_world)
        return self.center + depth[:, None] * rays_world


@dataclass(frozen=True)
class Camera(LookAtPose):
    """One simulated camera: pose by position/look-at, intrinsics, timing."""

    name: str
    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    resolution: tuple[int, int]
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    fps: float = 30.0
    start_offset_s: float = 0.0
    exposure_s: float = 0.01
    frame_jitter_s: float = 0.0
    drop_rate: float = 0.0
    readout_s: float = 0.0
    auto_exposure: AutoExposure | None = None
    crf: int | None = None

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def intrinsics(self) -> Intrinsics:
        return Intrinsics(self.name, self.resolution, self.K, np.array(self.dist))


@dataclass(frozen=True)
class CameraChange:
    """What happens to one camera between two recordings of a room: a lamp camera moved,
    a ceiling camera bumped, a PTZ camera re-zoomed.

    Attributes:
        pan_deg: turn about the vertical through its centre, degrees (positive: to its left).
        tilt_deg: turn about its horizontal image axis, degrees (positive: it looks up).
        shift_m: move of its centre (x, y, z), metres.
        zoom: its focal lengths multiplied by this (the principal point kept).
    """

    pan_deg: float = 0.0
    tilt_deg: float = 0.0
    shift_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    zoom: float = 1.0

    def __post_init__(self) -> None:
        values = (self.pan_deg, self.tilt_deg, *self.shift_m, self.zoom)
        if len(self.shift_m) != 3 or not all(math.isfinite(v) for v in values):
            raise ValueError("a camera change needs finite pan_deg, tilt_deg, zoom and three shift_m values")
        if not 0.1 <= self.zoom <= 10.0 or abs(self.tilt_deg) >= 80.0:
            raise ValueError(f"zoom must be in [0.1, 10] and |tilt_deg| < 80, got {self.zoom} and {self.tilt_deg}")

    def applied(self, camera: Camera) -> Camera:
        """``camera`` after this change."""
        position = np.asarray(camera.position, float)
        view = np.asarray(camera.look_at, float) - position
        pan = math.radians(self.pan_deg)
        turn = np.array([[math.cos(pan), -math.sin(pan), 0.0], [math.sin(pan), math.cos(pan), 0.0], [0.0, 0.0, 1.0]])
        view = turn @ view
        # Tilt about the camera's own horizontal axis (its image x axis, the first row of R).
        axis = look_at_rotation(position, position + view)[0]
        view = _rotated(view, axis, math.radians(self.tilt_deg))
        moved = position + np.asarray(self.shift_m, float)
        return replace(camera, position=tuple(moved.tolist()), look_at=tuple((moved + view).tolist()),
                       fx=camera.fx * self.zoom, fy=camera.fy * self.zoom)


def _rotated(vector: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """``vector`` turned by ``angle`` (radians) about the unit ``axis`` (Rodrigues)."""
    return (vector * math.cos(angle) + np.cross(axis, vector) * math.sin(angle)
            + axis * (axis @ vector) * (1.0 - math.cos(angle)))


@dataclass(frozen=True)
class Photometric:
    """How rendered frames look (used by the video renderer, ignored by the geometric simulator).

    Attributes:
        ambient: light on the floor with the projector black, fraction of full scale.
        contrast: projected white minus black on the floor, fraction of full scale.
        noise_std: sensor noise, grey levels (0-255).
        blur_px: Gaussian blur sigma (optics, focus), pixels.
        vignetting: brightness lost in the image corners, fraction.
        gamma: display gamma of the recorded video.
    """

    ambient: float = 0.05
    contrast: float = 0.8
    noise_std: float = 2.0
    blur_px: float = 0.7
    vignetting: float = 0.3
    gamma: float = 2.2


@dataclass(frozen=True)
class Scene:
    """A simulated room: floor, projector, cameras (unique names) and photometric settings."""

    floor: Floor
    projector: Projector
    cameras: tuple[Camera, ...]
    photometric: Photometric = field(default_factory=Photometric)
    people: tuple[Person, ...] = ()
    boxes: tuple[Box, ...] = ()

    @property
    def camera_names(self) -> list[str]:
        return [camera.name for camera in self.cameras]

    def camera(self, name: str) -> Camera:
        for camera in self.cameras:
            if camera.name == name:
                return camera
        raise KeyError(f"no camera {name!r} in the scene (cameras: {', '.join(self.camera_names)})")

    def subset(self, names: list[str]) -> Scene:
        """The same room with only the named cameras, in the given order."""
        return Scene(self.floor, self.projector, tuple(self.camera(name) for name in names), self.photometric,
                     self.people, self.boxes)

    def changed(self, changes: Mapping[str, CameraChange]) -> Scene:
        """The same room with the named cameras changed (a check's second recording);
        ValueError naming a camera the scene does not have."""
        unknown = sorted(set(changes) - set(self.camera_names))
        if unknown:
            raise ValueError(f"no camera {', '.join(unknown)} in the scene (cameras: {', '.join(self.camera_names)})")
        return replace(self, cameras=tuple(changes[c.name].applied(c) if c.name in changes else c
                                           for c in self.cameras))

    def to_json(self) -> dict[str, Any]:
        """Body of ``scene.json`` (without the schema tag)."""
        return {
            "floor": _without_none({"size_m": list(self.floor.size_m),
                                    "texture": None if self.floor.texture is None else asdict(self.floor.texture),
                                    "relief": None if self.floor.relief is None else asdict(self.floor.relief)}),
            "projector": {key: value for key, value in _plain(asdict(self.projector)).items()
                          if key != "dist" or any(self.projector.dist)},
            "cameras": [_without_none(_plain(asdict(camera))) for camera in self.cameras],
            "photometric": asdict(self.photometric),
            **({"people": [_plain(asdict(person)) for person in self.people]} if self.people else {}),
            **({"boxes": [_plain(asdict(box)) for box in self.boxes]} if self.boxes else {}),
        }


def _plain(record: dict[str, Any]) -> dict[str, Any]:
    return {key: list(value) if isinstance(value, tuple) else value for key, value in record.items()}


def _without_none(record: dict[str, Any]) -> dict[str, Any]:
    """Optional parts left out when absent, as a scene file may leave them out."""
    return {key: value for key, value in record.items() if value is not None}


def save_scene(path: str | os.PathLike, scene: Scene) -> None:
    """Write ``scene.json`` atomically."""
    write_json(path, SCHEMA_KIND, SCHEMA_MAJOR, scene.to_json())


def read_scene(path: str | os.PathLike) -> Scene:
    """Read and validate a scene file; errors name the file and the field."""
    document = read_json(path, SCHEMA_KIND, SCHEMA_MAJOR)
    return scene_from_json(document, source=str(path))


def load_scene(name_or_path: str | os.PathLike, seed: int | None = 0) -> Scene:
    """A built-in scene by name (see ``calibproj.simulate.presets``) or a scene file by path.

    ``seed`` drives the random parts of a preset (the camera angles of ``paper``); a
    scene file is read as it is.
    """
    if isinstance(name_or_path, str) and name_or_path in PRESETS:
        return scene_from_json(preset_document(name_or_path, seed), source=f"preset {name_or_path!r}")
    path = Path(name_or_path)
    if not path.is_file():
        raise ValueError(f"{path}: no such scene file, and not a preset ({', '.join(PRESETS)})")
    return read_scene(path)


def scene_from_json(document: dict[str, Any], source: str = "scene") -> Scene:
    """Validate a scene document; ``source`` names it in error messages."""
    reader = _FieldReader(source)
    known = {"schema", "floor", "projector", "cameras", "photometric", "people", "boxes"}
    reader.no_unknown_keys(document, known, "")
    floor = _read_floor(reader, reader.required(document, "floor", ""))
    projector = _read_projector(reader, reader.required(document, "projector", ""))
    cameras_json = reader.required(document, "cameras", "")
    if not isinstance(cameras_json, list) or not cameras_json:
        raise FormatError(f"{source}: cameras: expected a non-empty list")
    cameras = tuple(_read_camera(reader, entry, f"cameras[{i}]") for i, entry in enumerate(cameras_json))
    names = [camera.name for camera in cameras]
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise FormatError(f"{source}: cameras: duplicate names {duplicates}")
    photometric = _read_photometric(reader, document.get("photometric", {}))
    people_json = document.get("people", [])
    if not isinstance(people_json, list):
        raise FormatError(f"{source}: people: expected a list")
    people = tuple(_read_person(reader, entry, f"people[{i}]") for i, entry in enumerate(people_json))
    boxes_json = document.get("boxes", [])
    if not isinstance(boxes_json, list):
        raise FormatError(f"{source}: boxes: expected a list")
    boxes = tuple(_read_box(reader, entry, f"boxes[{i}]") for i, entry in enumerate(boxes_json))
    scene = Scene(floor, projector, cameras, photometric, people, boxes)
    _check_projector_hits_floor(source, scene.projector)
    return scene


def _read_floor(reader: _FieldReader, entry: Any) -> Floor:
    reader.no_unknown_keys(entry, {"size_m", "texture", "relief"}, "floor")
    size = tuple(reader.numbers(entry, "size_m", "floor", 2, positive=True))
    texture = _read_floor_texture(reader, entry["texture"]) if "texture" in entry else None
    relief = _read_floor_relief(reader, entry["relief"]) if "relief" in entry else None
    return Floor(size, texture, relief)


def _read_floor_relief(reader: _FieldReader, entry: Any) -> FloorRelief:
    where = "floor.relief"
    values = _read_record(reader, entry, FloorRelief(), where)
    # Beyond a few centimetres the floor is no longer "slightly uneven" and the
    # fixed-point ray steps may stop contracting.
    if not 0.0 <= values["rms_m"] <= 0.05:
        reader.fail(f"{where}.rms_m", f"expected a number in [0, 0.05], got {values['rms_m']}")
    if not values["wavelength_m"] >= 0.2:
        reader.fail(f"{where}.wavelength_m", f"expected a number of at least 0.2, got {values['wavelength_m']}")
    if values["seed"] != int(values["seed"]) or values["seed"] < 0:
        reader.fail(f"{where}.seed", f"expected a non-negative integer, got {values['seed']}")
    values.update(seed=int(values["seed"]))
    return FloorRelief(**values)


def _read_floor_texture(reader: _FieldReader, entry: Any) -> FloorTexture:
    where = "floor.texture"
    values = _read_record(reader, entry, FloorTexture(), where)
    for key in ("grout_albedo", "stain_albedo"):
        if not 0.0 <= values[key] <= 1.0:
            reader.fail(f"{where}.{key}", f"expected a number in [0, 1], got {values[key]}")
    for key in ("tile_m", "grout_m"):
        if values[key] <= 0.0:
            reader.fail(f"{where}.{key}", f"expected a positive number, got {values[key]}")
    if values["grout_m"] >= values["tile_m"]:
        reader.fail(f"{where}.grout_m", "must be narrower than the tiles")
    if not 0.0 <= values["tile_albedo_std"] <= 0.3:
        reader.fail(f"{where}.tile_albedo_std", f"expected a number in [0, 0.3], got {values['tile_albedo_std']}")
    if values["stains"] != int(values["stains"]) or not 0 <= values["stains"] <= 10000:
        reader.fail(f"{where}.stains", f"expected an integer in [0, 10000], got {values['stains']}")
    if values["seed"] != int(values["seed"]) or values["seed"] < 0:
        reader.fail(f"{where}.seed", f"expected a non-negative integer, got {values['seed']}")
    values.update(stains=int(values["stains"]), seed=int(values["seed"]))
    return FloorTexture(**values)


def _read_person(reader: _FieldReader, entry: Any, where: str) -> Person:
    reader.no_unknown_keys(entry, set(Person.__dataclass_fields__), where)
    start = tuple(reader.numbers(entry, "start", where, 2))
    end = tuple(reader.numbers(entry, "end", where, 2))
    defaults = Person(start, end)
    values = {}
    for key in ("start_s", "speed_mps", "radius_m", "height_m", "albedo"):
        values[key] = reader.number(entry, key, where, default=getattr(defaults, key))
    for key in ("speed_mps", "radius_m", "height_m"):
        if values[key] <= 0.0:
            reader.fail(f"{where}.{key}", f"expected a positive number, got {values[key]}")
    if not 0.0 <= values["albedo"] <= 1.0:
        reader.fail(f"{where}.albedo", f"expected a number in [0, 1], got {values['albedo']}")
    return Person(start, end, **values)


def _read_box(reader: _FieldReader, entry: Any, where: str) -> Box:
    reader.no_unknown_keys(entry, set(Box.__dataclass_fields__), where)
    centre = tuple(reader.numbers(entry, "centre", where, 2))
    size = tuple(reader.numbers(entry, "size_m", where, 3, positive=True))
    bottom = reader.number(entry, "bottom_m", where, default=0.0)
    albedo = reader.number(entry, "albedo", where, default=Box(centre, size).albedo)
    if bottom < 0.0:
        reader.fail(f"{where}.bottom_m", f"expected >= 0, got {bottom}")
    if not 0.0 <= albedo <= 1.0:
        reader.fail(f"{where}.albedo", f"expected a number in [0, 1], got {albedo}")
    return Box(centre, size, bottom, albedo)


def _read_record(reader: _FieldReader, entry: Any, defaults: Any, where: str) -> dict[str, float]:
    """The numeric fields of a dataclass record, defaults filled in, >= 0."""
    reader.no_unknown_keys(entry, set(asdict(defaults)), where)
    values = {}
    for key, default in asdict(defaults).items():
        value = reader.number(entry, key, where, default=default)
        if value < 0.0:
            reader.fail(f"{where}.{key}", f"expected >= 0, got {value}")
        values[key] = value
    return values


def _read_auto_exposure(reader: _FieldReader, entry: Any, where: str) -> AutoExposure:
    values = _read_record(reader, entry, AutoExposure(), where)
    if not 0.0 < values["target"] < 1.0:
        reader.fail(f"{where}.target", f"expected a number in (0, 1), got {values['target']}")
    if not 0.0 < values["min_gain"] <= values["initial_gain"] <= values["max_gain"]:
        reader.fail(where, "expected 0 < min_gain <= initial_gain <= max_gain")
    if not values["time_constant_s"] > 0.0:
        reader.fail(f"{where}.time_constant_s", "expected a positive number")
    return AutoExposure(**values)


def _read_projector(reader: _FieldReader, entry: Any) -> Projector:
    where = "projector"
    reader.no_unknown_keys(entry, {"position", "look_at", "resolution", "fx", "dist"}, where)
    position, look_at = _read_placement(reader, entry, where)
    resolution = _read_resolution(reader, entry, where)
    fx = reader.number(entry, "fx", where, positive=True)
    dist = (0.0, 0.0)
    if "dist" in entry:
        dist = tuple(reader.numbers(entry, "dist", where, 2))
        if any(abs(k) > 1.0 for k in dist):
            reader.fail(f"{where}.dist", "expected a projector lens's radial distortion [k1, k2], each within [-1, 1]")
    return Projector(position, look_at, resolution, fx, dist)


def _read_camera(reader: _FieldReader, entry: Any, where: str) -> Camera:
    known = {"name", "position", "look_at", "resolution", "fx", "fy", "cx", "cy", "dist", "fps",
             "start_offset_s", "exposure_s", "frame_jitter_s", "drop_rate", "readout_s", "auto_exposure", "crf"}
    reader.no_unknown_keys(entry, known, where)
    name = reader.required(entry, "name", where)
    if not isinstance(name, str) or not CAMERA_NAME_PATTERN.match(name):
        reader.fail(f"{where}.name", f"expected letters, digits, '_', '-' or '.' (a file name), got {name!r}")
    where = f"{where} ({name})"
    position, look_at = _read_placement(reader, entry, where)
    resolution = _read_resolution(reader, entry, where)
    fx = reader.number(entry, "fx", where, positive=True)
    fy = reader.number(entry, "fy", where, positive=True, default=fx)
    cx = reader.number(entry, "cx", where, default=(resolution[0] - 1) / 2.0)
    cy = reader.number(entry, "cy", where, default=(resolution[1] - 1) / 2.0)
    dist = tuple(reader.numbers(entry, "dist", where, None, default=[0.0] * 5))
    if len(dist) not in DISTORTION_LENGTHS:
        lengths = ", ".join(map(str, DISTORTION_LENGTHS))
        reader.fail(f"{where}.dist", f"expected {lengths} coefficients, got {len(dist)}")
    fps = reader.number(entry, "fps", where, positive=True, default=30.0)
    start_offset_s = reader.number(entry, "start_offset_s", where, default=0.0)
    exposure_s = reader.number(entry, "exposure_s", where, positive=True, default=min(0.01, 1.0 / fps))
    if exposure_s > 1.0 / fps:
        reader.fail(f"{where}.exposure_s", f"{exposure_s} s is longer than one frame at {fps} fps")
    jitter = reader.number(entry, "frame_jitter_s", where, default=0.0)
    # Jitter is clipped at 3 sigma: consecutive exposures must not overlap.
    if not 0.0 <= 6.0 * jitter <= 1.0 / fps - exposure_s:
        reader.fail(f"{where}.frame_jitter_s", f"expected a number in [0, {(1.0 / fps - exposure_s) / 6.0:.6g}] "
                    f"(6 sigma within the frame period minus the exposure), got {jitter}")
    drop_rate = reader.number(entry, "drop_rate", where, default=0.0)
    if not 0.0 <= drop_rate <= 0.5:
        reader.fail(f"{where}.drop_rate", f"expected a number in [0, 0.5], got {drop_rate}")
    readout_s = reader.number(entry, "readout_s", where, default=0.0)
    if not 0.0 <= readout_s <= 1.0 / fps:
        reader.fail(f"{where}.readout_s", f"expected a number in [0, {1.0 / fps:.6g}] (the rows are read "
                    f"within one frame at {fps} fps), got {readout_s}")
    crf = entry.get("crf")
    if crf is not None and (isinstance(crf, bool) or not isinstance(crf, int) or not 0 <= crf <= 51):
        reader.fail(f"{where}.crf", f"expected an integer in [0, 51], got {crf!r}")
    auto_exposure = None
    if "auto_exposure" in entry:
        auto_exposure = _read_auto_exposure(reader, entry["auto_exposure"], f"{where}.auto_exposure")
    return Camera(name, position, look_at, resolution, fx, fy, cx, cy, dist, fps, start_offset_s, exposure_s,
                  jitter, drop_rate, readout_s, auto_exposure, crf)


def _read_placement(reader: _FieldReader, entry: Any, where: str) -> tuple[tuple, tuple]:
    position = tuple(reader.numbers(entry, "position", where, 3))
    look_at = tuple(reader.numbers(entry, "look_at", where, 3))
    if position == look_at:
        reader.fail(f"{where}.look_at", "equals position; a device must look somewhere")
    return position, look_at


def _read_resolution(reader: _FieldReader, entry: Any, where: str) -> tuple[int, int]:
    values = reader.numbers(entry, "resolution", where, 2, positive=True)
    if any(v != int(v) for v in values):
        reader.fail(f"{where}.resolution", f"expected two integers [width, height], got {values}")
    return int(values[0]), int(values[1])


def _read_photometric(reader: _FieldReader, entry: Any) -> Photometric:
    where = "photometric"
    defaults = Photometric()
    reader.no_unknown_keys(entry, set(asdict(defaults)), where)
    values = {}
    for key, default in asdict(defaults).items():
        value = reader.number(entry, key, where, default=default)
        bounded = key in ("ambient", "contrast", "vignetting")
        if (bounded and not 0.0 <= value <= 1.0) or value < 0.0 or (key == "gamma" and value == 0.0):
            expected = "a number in [0, 1]" if bounded else "a positive number" if key == "gamma" else ">= 0"
            reader.fail(f"{where}.{key}", f"expected {expected}, got {value}")
        values[key] = value
    return Photometric(**values)


def _check_projector_hits_floor(source: str, projector: Projector) -> None:
    width, height = projector.resolution
    corners = np.array([[0, 0], [width - 1, 0], [width - 1, height - 1], [0, height - 1]], dtype=float)
    if projector.position[2] <= 0 or np.isnan(projector.pixels_to_floor(corners)).any():
        raise FormatError(
            f"{source}: projector: its whole image must fall on the floor (z = 0); "
            "place it above the floor looking down"
        )


class _FieldReader:
    """Typed access to JSON fields with errors of the form ``<file>: <field>: <problem>``."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, problem: str) -> None:
        raise FormatError(f"{self.source}: {where}: {problem}")

    def no_unknown_keys(self, entry: Any, known: set[str], where: str) -> None:
        if not isinstance(entry, dict):
            self.fail(where or "scene", "expected a JSON object")
        unknown = sorted(set(entry) - known)
        if unknown:
            self.fail(where or "scene", f"unknown field(s) {unknown} (known: {sorted(known)})")

    def required(self, entry: dict[str, Any], key: str, where: str) -> Any:
        if key not in entry:
            self.fail(_join(where, key), "missing")
        return entry[key]

    def number(self, entry: dict[str, Any], key: str, where: str, positive: bool = False,
               default: float | None = None) -> float:
        value = entry.get(key, default) if default is not None else self.required(entry, key, where)
        return self.check_number(value, _join(where, key), positive)

    def numbers(self, entry: Any, key: str, where: str, count: int | None, positive: bool = False,
                default: list[float] | None = None) -> list[float]:
        if not isinstance(entry, dict):
            self.fail(where, "expected a JSON object")
        value = entry.get(key, default) if default is not None else self.required(entry, key, where)
        if not isinstance(value, list) or (count is not None and len(value) != count):
            size = f"{count} numbers" if count is not None else "a list of numbers"
            self.fail(_join(where, key), f"expected {size}, got {value!r}")
        return [self.check_number(v, f"{_join(where, key)}[{i}]", positive) for i, v in enumerate(value)]

    def check_number(self, value: Any, where: str, positive: bool) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            self.fail(where, f"expected a number, got {value!r}")
        if positive and value <= 0:
            self.fail(where, f"expected a positive number, got {value}")
        return float(value)


def _join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key
