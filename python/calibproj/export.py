"""Export a calibration to the formats of other tools.

Every format holds the registered cameras only (a failed camera has no pose), with
world-to-camera poses ``x_cam = R X + t`` in the calibration's floor frame and unit
(metres after ``--scale``, arbitrary otherwise).

``yaml`` -> ``calibration_opencv.yaml``
    One ``cv2.FileStorage`` file: ``schema``, ``unit``, ``frame``, ``camera_count`` and
    a sequence ``cameras`` of maps with ``name``, ``image_width``, ``image_height``,
    ``camera_matrix`` (3x3), ``distortion_coefficients`` (1xN, OpenCV order), ``R``
    (3x3), ``t`` (3x1) and ``rvec`` (3x1, Rodrigues of R). The per-camera keys are the
    ones OpenCV calibration tools write, so one entry reads like an intrinsics file.

``colmap`` -> ``colmap/cameras.txt``, ``colmap/images.txt``, ``colmap/points3D.txt``
    COLMAP's text model. One COLMAP camera and one image per camera (image name = the
    camera name). Camera model ``PINHOLE`` without distortion, ``OPENCV`` with
    k1, k2, p1, p2 only, ``FULL_OPENCV`` when k3 or the rational terms are used (COLMAP's
    OPENCV model has no k3); thin-prism and tilt terms have no COLMAP model and are
    refused. COLMAP puts the centre of the top-left pixel at (0.5, 0.5) where OpenCV
    puts it at (0, 0), so principal points and 2D points are shifted by half a pixel.
    ``images.txt`` holds the pose as the quaternion ``QW QX QY QZ`` (w >= 0) and ``T``
    of the same world-to-camera convention; with tracks, each image lists its
    observations as distorted image points (COLMAP applies the camera model itself),
    and ``points3D.txt`` gives every point its track and its mean reprojection error
    (undistorted pixels). Point ids are the calibration's point ids.

``anipose`` -> ``calibration.toml``
    aniposelib's ``CameraGroup.dump`` layout, for multi-view pose triangulation: one
    table ``cam_<i>`` per camera with ``name``, ``size`` ([width, height]), ``matrix``,
    ``distortions``, ``rotation`` (Rodrigues vector) and ``translation``, and a
    ``metadata`` table (``adjusted``, ``error`` = mean reprojection error of the inlier
    observations in pixels, plus
    ``unit``, ``frame`` and ``source``). Triangulated points come out in the
    calibration's unit.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from calibproj.calibration import Calibration
from calibproj.io.intrinsics import Intrinsics
from calibproj.io.jsonio import atomic_write_text
from calibproj.reprojection import reprojection_errors
from calibproj.tracks import Tracks

logger = logging.getLogger(__name__)

FORMATS = ("yaml", "colmap", "anipose")
YAML_FILE = "calibration_opencv.yaml"
YAML_SCHEMA = "calibproj.opencv_calibration/1"
COLMAP_DIR = "colmap"
ANIPOSE_FILE = "calibration.toml"

# OpenCV pixel (0, 0) is the centre of the top-left pixel; COLMAP puts it at (0.5, 0.5).
COLMAP_PIXEL_SHIFT = 0.5
# Colour given to every point in points3D.txt (the points carry no colour).
COLMAP_POINT_RGB = (200, 200, 200)


def parse_formats(text: str) -> list[str]:
    """``"yaml,colmap"`` -> ``["yaml", "colmap"]``; ValueError naming an unknown format."""
    formats = [part.strip() for part in text.split(",") if part.strip()]
    unknown = [f for f in formats if f not in FORMATS]
    if unknown or not formats:
        raise ValueError(f"export format {unknown[0] if unknown else text!r} unknown (expected a comma-separated "
                         f"list of {', '.join(FORMATS)})")
    return list(dict.fromkeys(formats))


def export(
    calibration: Calibration,
    format_name: str,
    out_dir: str | os.PathLike,
    intrinsics: Mapping[str, Intrinsics],
    tracks: Tracks | None = None,
) -> list[Path]:
    """Write the calibration in ``format_name`` (``yaml``, ``colmap`` or ``anipose``) into
    ``out_dir``; returns the files written. ``tracks`` (the calibration's) give COLMAP
    its 2D points and tracks; the other formats do not use them."""
    if format_name not in FORMATS:
        raise ValueError(f"export format {format_name!r} unknown (expected one of {', '.join(FORMATS)})")
    missing = [name for name in calibration.poses if name not in intrinsics]
    if missing:
        raise ValueError(f"no intrinsics for registered camera(s) {', '.join(missing)}")
    if not calibration.poses:
        raise ValueError("no registered camera to export")
    out_dir = Path(out_dir)
    writer = {"yaml": write_opencv_yaml, "colmap": write_colmap, "anipose": write_anipose_toml}[format_name]
    files = writer(calibration, out_dir, intrinsics, tracks)
    logger.info("exported %s: %s", format_name, ", ".join(str(f) for f in files))
    return files


def export_all(calibration: Calibration, formats: Iterable[str], out_dir: str | os.PathLike,
               intrinsics: Mapping[str, Intrinsics], tracks: Tracks | None = None) -> list[Path]:
    """``export`` in every format of ``formats``."""
    return [path for f in formats for path in export(calibration, f, out_dir, intrinsics, tracks)]


def image_size(intrinsics: Intrinsics) -> tuple[int, int]:
    """The image size, or, for files that do not give one, twice the principal point."""
    if intrinsics.resolution is not None:
        return intrinsics.resolution
    logger.warning("camera %s: no image size in its intrinsics; using twice the principal point", intrinsics.name)
    return int(round(2.0 * intrinsics.K[0, 2] + 1.0)), int(round(2.0 * intrinsics.K[1, 2] + 1.0))


def rodrigues(R: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.Rodrigues(np.asarray(R, dtype=float))[0].ravel()


# -- OpenCV YAML ----------------------------------------------------------------------------


def write_opencv_yaml(calibration: Calibration, out_dir: Path, intrinsics: Mapping[str, Intrinsics],
                      tracks: Tracks | None = None) -> list[Path]:
    import cv2

    storage = cv2.FileStorage(YAML_FILE, cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    storage.write("schema", YAML_SCHEMA)
    storage.write("unit", calibration.unit)
    storage.write("frame", "floor")
    storage.write("pose_convention", "x_cam = R * X_world + t")
    storage.write("camera_count", len(calibration.poses))
    storage.startWriteStruct("cameras", cv2.FileNode_SEQ)
    for name, (R, t) in calibration.poses.items():
        camera = intrinsics[name]
        width, height = image_size(camera)
        storage.startWriteStruct("", cv2.FileNode_MAP)
        storage.write("name", name)
        storage.write("image_width", int(width))
        storage.write("image_height", int(height))
        storage.write("camera_matrix", np.asarray(camera.K, dtype=float))
        storage.write("distortion_coefficients", np.asarray(camera.dist, dtype=float).reshape(1, -1))
        storage.write("R", np.asarray(R, dtype=float))
        storage.write("t", np.asarray(t, dtype=float).reshape(3, 1))
        storage.write("rvec", rodrigues(R).reshape(3, 1))
        storage.endWriteStruct()
    storage.endWriteStruct()
    path = out_dir / YAML_FILE
    atomic_write_text(path, storage.releaseAndGetString())
    return [path]


# -- COLMAP text model ----------------------------------------------------------------------


def colmap_camera(intrinsics: Intrinsics) -> tuple[str, list[float]]:
    """COLMAP camera model and parameters of one camera (pixel centres shifted by 0.5)."""
    fx, fy = intrinsics.K[0, 0], intrinsics.K[1, 1]
    cx, cy = intrinsics.K[0, 2] + COLMAP_PIXEL_SHIFT, intrinsics.K[1, 2] + COLMAP_PIXEL_SHIFT
    dist = np.zeros(max(8, intrinsics.dist.size))
    dist[: intrinsics.dist.size] = intrinsics.dist
    if np.any(dist[8:] != 0.0):
        raise ValueError(f"camera {intrinsics.name}: thin-prism or tilt distortion has no COLMAP camera model")
    if not np.any(dist != 0.0):
        return "PINHOLE", [fx, fy, cx, cy]
    if not np.any(dist[4:] != 0.0):
        return "OPENCV", [fx, fy, cx, cy, *dist[:4]]
    return "FULL_OPENCV", [fx, fy, cx, cy, *dist[:8]]


def quaternion_wxyz(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(w, x, y, z)`` of a rotation matrix, with ``w >= 0``."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(np.asarray(R, dtype=float)).as_quat()
    q = np.array([w, x, y, z])
    return -q if w < 0 else q


def write_colmap(calibration: Calibration, out_dir: Path, intrinsics: Mapping[str, Intrinsics],
                 tracks: Tracks | None = None) -> list[Path]:
    folder = out_dir / COLMAP_DIR
    names = list(calibration.poses)
    observations = _colmap_observations(calibration, tracks, intrinsics)
    files = [folder / "cameras.txt", folder / "images.txt", folder / "points3D.txt"]
    atomic_write_text(files[0], _colmap_cameras_text(names, intrinsics))
    atomic_write_text(files[1], _colmap_images_text(calibration, names, observations))
    atomic_write_text(files[2], _colmap_points_text(calibration, names, observations))
    return files


def _colmap_observations(calibration: Calibration, tracks: Tracks | None,
                         intrinsics: Mapping[str, Intrinsics]) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per camera: point ids, COLMAP pixels (distorted, shifted) and reprojection errors."""
    if tracks is None:
        return {}
    out = {}
    for name, (ids, xy, residual) in reprojection_errors(calibration, tracks, intrinsics).items():
        pixels = intrinsics[name].distort_points(xy) + COLMAP_PIXEL_SHIFT
        out[name] = (ids, pixels, np.linalg.norm(residual, axis=1))
    return out


def _colmap_cameras_text(names: list[str], intrinsics: Mapping[str, Intrinsics]) -> str:
    lines = ["# Camera list with one line of data per camera:",
             "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]",
             f"# Number of cameras: {len(names)}"]
    for camera_id, name in enumerate(names, start=1):
        model, params = colmap_camera(intrinsics[name])
        width, height = image_size(intrinsics[name])
        lines.append(f"{camera_id} {model} {width} {height} " + " ".join(_number(p) for p in params))
    return "\n".join(lines) + "\n"


def _colmap_images_text(calibration: Calibration, names: list[str],
                        observations: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]) -> str:
    count = sum(len(observations[name][0]) for name in names if name in observations)
    lines = ["# Image list with two lines of data per image:",
             "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
             "#   POINTS2D[] as (X, Y, POINT3D_ID)",
             f"# Number of images: {len(names)}, mean observations per image: {count / len(names):g}"]
    for image_id, name in enumerate(names, start=1):
        R, t = calibration.poses[name]
        pose = [*quaternion_wxyz(R), *np.asarray(t, dtype=float)]
        lines.append(f"{image_id} " + " ".join(_number(v) for v in pose) + f" {image_id} {name}")
        ids, pixels, _ = observations.get(name, (np.zeros(0, dtype=np.int64), np.zeros((0, 2)), None))
        lines.append(" ".join(f"{_number(x)} {_number(y)} {int(i)}" for (x, y), i in zip(pixels, ids)))
    return "\n".join(lines) + "\n"


def _colmap_points_text(calibration: Calibration, names: list[str],
                        observations: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]) -> str:
    tracks: dict[int, list[tuple[int, int]]] = {int(i): [] for i in calibration.point_ids}
    errors: dict[int, list[float]] = {int(i): [] for i in calibration.point_ids}
    for image_id, name in enumerate(names, start=1):
        ids, _, error = observations.get(name, (np.zeros(0, dtype=np.int64), None, np.zeros(0)))
        for index, (point_id, e) in enumerate(zip(ids.tolist(), error.tolist())):
            tracks[point_id].append((image_id, index))
            errors[point_id].append(e)
    mean_track = np.mean([len(t) for t in tracks.values()]) if tracks else 0.0
    lines = ["# 3D point list with one line of data per point:",
             "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)",
             f"# Number of points: {len(tracks)}, mean track length: {mean_track:g}"]
    r, g, b = COLMAP_POINT_RGB
    for point_id, xyz in zip(calibration.point_ids.tolist(), calibration.points):
        error = float(np.mean(errors[point_id])) if errors[point_id] else 0.0
        track = " ".join(f"{image} {index}" for image, index in tracks[point_id])
        coordinates = " ".join(_number(v) for v in xyz)
        lines.append(f"{point_id} {coordinates} {r} {g} {b} {_number(error)} {track}".rstrip())
    return "\n".join(lines) + "\n"


def _number(value: float) -> str:
    """Full double precision, shortest form."""
    return repr(float(value))


# -- aniposelib calibration.toml ------------------------------------------------------------


def write_anipose_toml(calibration: Calibration, out_dir: Path, intrinsics: Mapping[str, Intrinsics],
                       tracks: Tracks | None = None) -> list[Path]:
    import tomli_w

    document: dict[str, Any] = {}
    for index, (name, (R, t)) in enumerate(calibration.poses.items()):
        camera = intrinsics[name]
        document[f"cam_{index}"] = {
            "name": name,
            "size": [int(v) for v in image_size(camera)],
            "matrix": np.asarray(camera.K, dtype=float).tolist(),
            "distortions": np.asarray(camera.dist, dtype=float).tolist(),
            "rotation": rodrigues(R).tolist(),
            "translation": np.asarray(t, dtype=float).tolist(),
        }
    document["metadata"] = {
        "adjusted": True,  # the poses come out of a bundle adjustment
        "error": _mean_error(calibration),
        "unit": calibration.unit,
        "frame": "floor",
        "source": "calibproj",
    }
    path = out_dir / ANIPOSE_FILE
    atomic_write_text(path, tomli_w.dumps(document))
    return [path]


def _mean_error(calibration: Calibration) -> float:
    """Mean reprojection error of the calibration's inlier observations, pixels."""
    rows = [(m.mean_px, m.inliers) for m in calibration.metrics.values() if m.mean_px is not None and m.inliers]
    if not rows:
        return 0.0
    means, counts = np.array(rows, dtype=float).T
    return float(np.sum(means * counts) / np.sum(counts))
