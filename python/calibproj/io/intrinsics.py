"""Camera intrinsics: the pinhole + OpenCV distortion model, and its file formats.

Three formats are read (see docs/conventions.md):

- ours, ``intrinsics/<camera>.json`` (``calibproj.intrinsics/1``);
- OpenCV YAML/XML written by ``cv2.FileStorage`` (``camera_matrix`` or ``K``,
  ``distortion_coefficients`` or ``D``, ``image_width``, ``image_height``);
- the reference code's JSON (``sensors.RGB.intrinsics.data`` and
  ``sensors.RGB.distortionCoefficients.data``), which carries no resolution.

Only ours is written. The files are read by the C++ core
(``cpp/calibproj/formats/intrinsics_file.cc``), as ``calibproj-native`` reads them.
OpenCV is imported inside the functions that need it so that importing this module
stays cheap.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibproj.io.jsonio import FormatError

# OpenCV accepts distortion vectors of these lengths:
# [k1 k2 p1 p2], + k3, + k4 k5 k6 (rational), + s1..s4 (thin prism), + tau_x tau_y (tilt).
DISTORTION_LENGTHS = (4, 5, 8, 12, 14)

# Iterative undistortion stops when the point, distorted again, lands within this many
# pixels of the input, or after this many iterations. OpenCV's default (5 iterations)
# leaves errors of several pixels in the corners of a wide-angle image.
UNDISTORT_EPS_PX = 1e-9
UNDISTORT_MAX_ITERATIONS = 200


# Image sides the C++ core takes (calibproj/common/limits.h, kMaxImageSide), pixels.
MAX_IMAGE_SIDE = 1 << 16


@dataclass(frozen=True, eq=False)  # numpy fields: compare K and dist explicitly
class Intrinsics:
    """One camera's pinhole matrix and OpenCV distortion.

    Attributes:
        name: camera name (the file stem when read from a directory).
        resolution: image size ``(width, height)`` in pixels; ``None`` when the file
            does not say (the reference code's format).
        K: 3x3 camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (no skew, as OpenCV).
        dist: distortion coefficients in OpenCV order, length 4, 5, 8, 12 or 14.
    """

    name: str
    resolution: tuple[int, int] | None
    K: np.ndarray
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))

    def __post_init__(self) -> None:
        K = np.array(self.K, dtype=float).reshape(3, 3)
        dist = np.array(self.dist, dtype=float).ravel()
        if dist.size == 0:
            dist = np.zeros(5)
        problem = _intrinsics_problem(K, dist, self.resolution)
        if problem:
            raise ValueError(f"intrinsics of {self.name!r}: {problem}")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "dist", dist)
        if self.resolution is not None:
            object.__setattr__(self, "resolution", (int(self.resolution[0]), int(self.resolution[1])))

    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.dist != 0.0))

    def undistort_points(self, pixels: np.ndarray) -> np.ndarray:
        """Undistorted pixel coordinates (same K) of distorted pixels, shape ``(N, 2)``.

        Iterates until the result, distorted again, is within ``UNDISTORT_EPS_PX`` of
        the input (a fixed-point iteration; it converges wherever the distortion is
        one-to-one, see ``max_monotonic_radius``).
        """
        import cv2

        pixels = _as_points(pixels)
        if pixels.shape[0] == 0 or not self.has_distortion:
            return pixels.copy()
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, UNDISTORT_MAX_ITERATIONS, UNDISTORT_EPS_PX)
        out = cv2.undistortPointsIter(
            pixels.reshape(-1, 1, 2), self.K, self.dist, np.eye(3), self.K, criteria
        )
        return out.reshape(-1, 2)

    def distort_points(self, pixels: np.ndarray) -> np.ndarray:
        """Distorted pixel coordinates of undistorted pixels (same K), shape ``(N, 2)``."""
        pixels = _as_points(pixels)
        if pixels.shape[0] == 0 or not self.has_distortion:
            return pixels.copy()
        return self.project_normalized(self.normalize(pixels))

    def normalize(self, pixels: np.ndarray) -> np.ndarray:
        """Pinhole normalised coordinates ``K^-1 [u, v, 1]`` of undistorted pixels."""
        pixels = _as_points(pixels)
        return (pixels - self.K[:2, 2]) / np.diag(self.K)[:2]

    def project_normalized(self, xy: np.ndarray) -> np.ndarray:
        """Distorted pixels of normalised coordinates ``(X/Z, Y/Z)``, shape ``(N, 2)``."""
        xy = _as_points(xy)
        if self.dist.size == 14 and np.any(self.dist[12:] != 0.0):
            return self._project_normalized_tilted(xy)
        distorted = _distort_normalized(xy, self.dist)
        return distorted @ self.K[:2, :2].T + self.K[:2, 2]

    def _project_normalized_tilted(self, xy: np.ndarray) -> np.ndarray:
        """The tilted-sensor model (14 coefficients) through OpenCV."""
        import cv2

        if xy.shape[0] == 0:
            return xy.copy()
        rays = np.column_stack([xy, np.ones(len(xy))])
        out, _ = cv2.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), self.K, self.dist)
        return out.reshape(-1, 2)

    def max_monotonic_radius(self, limit: float = 4.0, step: float = 1e-3) -> float:
        """Normalised radius up to which the radial distortion is one-to-one.

        A polynomial distortion folds back beyond some radius, so points far outside
        the field of view can land inside the image; callers reject points beyond
        this radius. Returns ``limit`` when the model stays monotonic up to it.
        """
        radius = np.arange(step, limit + step, step)
        distorted = radius * _radial_factor(self.dist, radius**2)
        increasing = np.diff(distorted) > 0
        if np.all(increasing) and np.all(np.isfinite(distorted)):
            return float(limit)
        return float(radius[int(np.argmin(increasing))])

    def contains(self, pixels: np.ndarray, margin_px: float = 0.0) -> np.ndarray:
        """Which pixels lie inside the image, ``margin_px`` away from its border."""
        if self.resolution is None:
            raise ValueError(f"intrinsics of {self.name!r}: resolution unknown")
        pixels = _as_points(pixels)
        width, height = self.resolution
        return (
            (pixels[:, 0] >= margin_px)
            & (pixels[:, 0] <= width - 1 - margin_px)
            & (pixels[:, 1] >= margin_px)
            & (pixels[:, 1] <= height - 1 - margin_px)
        )

    def to_json(self) -> dict[str, Any]:
        """Body of our intrinsics file (without the schema tag); ``resolution`` is None
        when not known."""
        return {
            "camera": self.name,
            "resolution": None if self.resolution is None else list(self.resolution),
            "K": self.K.tolist(),
            "dist": self.dist.tolist(),
        }


def _as_points(points: np.ndarray) -> np.ndarray:
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 2:
        points = points.reshape(-1, 2)
    return points


def _distort_normalized(xy: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """OpenCV's lens distortion (radial, tangential, thin prism) of normalised coordinates."""
    coefficients = np.zeros(12)
    coefficients[: min(len(dist), 12)] = dist[:12]
    _, _, p1, p2, _, _, _, _, s1, s2, s3, s4 = coefficients
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    radial = _radial_factor(dist, r2)
    x_out = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) + r2 * (s1 + s2 * r2)
    y_out = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y + r2 * (s3 + s4 * r2)
    return np.column_stack([x_out, y_out])


def _radial_factor(dist: np.ndarray, r2: np.ndarray) -> np.ndarray:
    """OpenCV's radial factor (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)."""
    coefficients = np.zeros(8)
    coefficients[: min(len(dist), 8)] = dist[:8]
    k1, k2, _, _, k3, k4, k5, k6 = coefficients
    numerator = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    denominator = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    with np.errstate(divide="ignore", invalid="ignore"):
        return numerator / denominator


def _intrinsics_problem(K: np.ndarray, dist: np.ndarray, resolution: Any) -> str | None:
    """What is wrong with these values, or ``None``."""
    if not np.all(np.isfinite(K)) or not np.all(np.isfinite(dist)):
        return "K and dist must be finite numbers"
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        return f"focal lengths must be positive, got fx={K[0, 0]}, fy={K[1, 1]}"
    if K[0, 1] != 0 or K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
        # OpenCV's distortion functions ignore a skew term, so none is accepted.
        return f"K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}"
    if dist.size not in DISTORTION_LENGTHS:
        return f"dist must have {', '.join(map(str, DISTORTION_LENGTHS))} coefficients, got {dist.size}"
    if resolution is not None:
        if len(resolution) != 2 or not all(math.isfinite(v) and v == int(v) and v > 0 for v in resolution):
            return f"resolution must be two positive integers [width, height], got {resolution}"
    # Without a resolution the principal point gives the image size (image_size).
    sides = resolution if resolution is not None else (2.0 * K[0, 2] + 1.0, 2.0 * K[1, 2] + 1.0)
    if not all(0 < side <= MAX_IMAGE_SIDE for side in sides):
        return f"image size must be at most {MAX_IMAGE_SIDE} pixels per side, got {sides[0]:g}x{sides[1]:g}"
    return None


def image_size(intrinsics: Intrinsics) -> tuple[float, float]:
    """The camera's image size, or twice its principal point when the file gives none."""
    if intrinsics.resolution is not None:
        return float(intrinsics.resolution[0]), float(intrinsics.resolution[1])
    return 2.0 * float(intrinsics.K[0, 2]) + 1.0, 2.0 * float(intrinsics.K[1, 2]) + 1.0


def read_intrinsics(path: str | os.PathLike, name: str | None = None) -> Intrinsics:
    """Read one intrinsics file in any supported format (by the C++ core, as
    ``calibproj-native`` reads it); the name defaults to the file stem."""
    from calibproj import _core

    core = _core.formats.read_intrinsics(Path(path), name or "")
    return intrinsics_from_core(core)


def write_intrinsics(path: str | os.PathLike, intrinsics: Intrinsics, extra: Mapping[str, Any] | None = None) -> None:
    """Write our intrinsics format atomically (by the C++ core, as ``calibproj-native``
    writes it); the entries of ``extra`` (how the intrinsics were measured, their
    uncertainty) follow the format's own."""
    from calibproj import _core

    _core.formats.write_intrinsics(Path(path), intrinsics, json.dumps(dict(extra)) if extra else "")


def write_intrinsics_dir(directory: str | os.PathLike, cameras: dict[str, Intrinsics]) -> None:
    """Write ``<directory>/<camera>.json`` for every camera."""
    for camera_name, intrinsics in cameras.items():
        write_intrinsics(Path(directory) / f"{camera_name}.json", intrinsics)


def load_intrinsics_dir(directory: str | os.PathLike) -> dict[str, Intrinsics]:
    """All intrinsics files of a directory, keyed by camera name (the file stem); the
    first bad file is a FormatError."""
    cameras, unusable = intrinsics_of_cameras(directory, intrinsics_files_in(directory))
    for reason in unusable.values():
        raise FormatError(reason)
    return cameras


def intrinsics_of_cameras(
    source: Mapping[str, Intrinsics] | str | os.PathLike, names: Iterable[str]
) -> tuple[dict[str, Intrinsics], dict[str, str]]:
    """The intrinsics of the named cameras, from a mapping or a directory, and why the
    others have none: ``(name -> Intrinsics, name -> reason)``. A bad, missing or
    doubled file fails its own camera only, the reason naming the file and the problem.

    Raises:
        FormatError: ``source`` is no directory, or one without any intrinsics file.
    """
    names = list(dict.fromkeys(names))
    if isinstance(source, Mapping):
        found = {name: source[name] for name in names if name in source}
        known = ", ".join(sorted(source)) or "none"
        return found, {name: f"no intrinsics for camera {name!r} (cameras with intrinsics: {known})"
                       for name in names if name not in source}
    directory = Path(source)
    intrinsics_files_in(directory)  # the folder exists and holds intrinsics files
    cameras: dict[str, Intrinsics] = {}
    unusable: dict[str, str] = {}
    for name in names:
        try:
            cameras[name] = read_intrinsics(intrinsics_file(directory, name), name)
        except FormatError as error:
            unusable[name] = str(error)
    return cameras, unusable


def has_intrinsics_file(source: Mapping[str, Intrinsics] | str | os.PathLike, name: str) -> bool:
    """Whether ``source`` (a mapping or a folder) has intrinsics, good or bad, for ``name``."""
    if isinstance(source, Mapping):
        return name in source
    try:
        return name in intrinsics_files_in(source)
    except FormatError:  # no folder, or none of its files is an intrinsics file
        return False


def intrinsics_file(directory: str | os.PathLike, name: str) -> Path:
    """The one intrinsics file of camera ``name`` in ``directory`` (the C++ core's lookup,
    which calibproj-native uses too); FormatError naming the folder or the file when
    there is none, or more than one."""
    from calibproj import _core

    try:
        return Path(_core.formats.intrinsics_file(Path(directory), name))
    except ValueError as error:
        raise FormatError(str(error)) from None


def intrinsics_files_in(directory: str | os.PathLike) -> dict[str, list[Path]]:
    """Camera name -> its intrinsics files in ``directory`` (one, normally)."""
    from calibproj import _core

    try:
        files = _core.formats.intrinsics_files(Path(directory))
    except ValueError as error:
        raise FormatError(str(error)) from None
    return {name: [Path(path) for path in paths] for name, paths in files.items()}


def intrinsics_from_json(document: Any, name: str, where: str | os.PathLike) -> Intrinsics:
    """The intrinsics of the body of our format (``Intrinsics.to_json``), checked by the
    C++ core as a file is; FormatError naming ``where`` and the problem."""
    from calibproj import _core

    try:
        core = _core.formats.intrinsics_from_json(json.dumps(document), name)
    except (TypeError, ValueError) as error:
        raise FormatError(f"{where}: {error}") from None
    return intrinsics_from_core(core)


def intrinsics_from_core(core: Any) -> Intrinsics:
    """An Intrinsics from the core's ``_core.formats.CameraIntrinsics``."""
    return Intrinsics(core.name, core.resolution, np.array(core.K), np.array(core.dist, dtype=float))
