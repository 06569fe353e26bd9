"""Intrinsics: the three file formats, directory loading, and (un)distortion accuracy."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from calibproj.formats.intrinsics import (
    Intrinsics,
    intrinsics_of_cameras,
    load_intrinsics_dir,
    read_intrinsics,
    write_intrinsics,
)

K_GOPRO = np.array([[915.0, 0.0, 962.6], [0.0, 915.6, 537.1], [0.0, 0.0, 1.0]])
DIST_GOPRO = np.array([-0.26, 0.09, 0.0003, -0.0002, -0.012])


def gopro() -> Intrinsics:
    return Intrinsics("far1", (1920, 1080), K_GOPRO, DIST_GOPRO)


def image_grid(width: int, height: int, step: float) -> np.ndarray:
    """Pixels covering the whole image, its outer pixel edges and corners included."""
    u = np.append(np.arange(-0.5, width - 0.5, step), width - 0.5)
    v = np.append(np.arange(-0.5, height - 0.5, step), height - 0.5)
    return np.stack(np.meshgrid(u, v), axis=-1).reshape(-1, 2)


def test_undistortion_inverts_gopro_distortion_to_a_micro_pixel():
    intrinsics = gopro()
    distorted = image_grid(1920, 1080, 16.0)
    undistorted = intrinsics.undistort_points(distorted)
    # The corners of this lens move by ~500 px, so the iteration has real work to do.
    assert np.abs(undistorted - distorted).max() > 300.0
    assert np.abs(intrinsics.distort_points(undistorted) - distorted).max() < 1e-6
    again = intrinsics.undistort_points(intrinsics.distort_points(undistorted))
    assert np.abs(again - undistorted).max() < 1e-6


@pytest.mark.parametrize(
    "dist",
    [
        DIST_GOPRO,
        [-0.2, 0.05, 0.001, -0.002, 0.01, 0.02, -0.01, 0.003],
        [-0.2, 0.05, 0.001, -0.002, 0.01, 0.02, -0.01, 0.003, 0.001, -0.002, 0.003, 0.0005],
        [-0.1, 0.02, 0.001, -0.002, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.01, -0.02],
    ],
)
def test_distortion_matches_opencv(dist):
    intrinsics = Intrinsics("cam", (1920, 1080), K_GOPRO, dist)
    xy = np.random.default_rng(0).uniform(-1.0, 1.0, size=(500, 2))
    expected, _ = cv2.projectPoints(
        np.column_stack([xy, np.ones(len(xy))]), np.zeros(3), np.zeros(3), K_GOPRO, np.asarray(dist, dtype=float)
    )
    np.testing.assert_allclose(intrinsics.project_normalized(xy), expected.reshape(-1, 2), atol=1e-9)


def test_gopro_lens_is_one_to_one_over_its_image():
    intrinsics = gopro()
    corners = intrinsics.undistort_points(np.array([[-0.5, -0.5], [1919.5, 1079.5]]))
    assert np.linalg.norm(intrinsics.normalize(corners), axis=1).max() < intrinsics.max_monotonic_radius()
    pinhole = Intrinsics("pinhole", (640, 360), np.diag([305.0, 305.0, 1.0]), [0.0] * 5)
    assert pinhole.max_monotonic_radius() == 4.0


def test_our_json_round_trip(tmp_path):
    path = tmp_path / "far1.json"
    write_intrinsics(path, gopro())
    document = json.loads(path.read_text())
    assert document["schema"] == "calibproj.intrinsics/1" and document["camera"] == "far1"
    read = read_intrinsics(path)
    assert read.name == "far1" and read.resolution == (1920, 1080)
    np.testing.assert_array_equal(read.K, K_GOPRO)
    np.testing.assert_array_equal(read.dist, DIST_GOPRO)


@pytest.mark.parametrize(("matrix_key", "dist_key", "suffix"), [
    ("camera_matrix", "distortion_coefficients", ".yaml"),
    ("K", "D", ".yml"),
    ("camera_matrix", "distortion_coefficients", ".xml"),
])
def test_opencv_storage_round_trip(tmp_path, matrix_key, dist_key, suffix):
    path = tmp_path / f"near1{suffix}"
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    storage.write("image_width", 1920)
    storage.write("image_height", 1080)
    storage.write(matrix_key, K_GOPRO)
    storage.write(dist_key, DIST_GOPRO.reshape(1, 5))
    storage.release()
    read = read_intrinsics(path)
    assert read.name == "near1" and read.resolution == (1920, 1080)
    np.testing.assert_allclose(read.K, K_GOPRO)
    np.testing.assert_allclose(read.dist, DIST_GOPRO)


def test_reference_code_json(tmp_path):
    path = tmp_path / "ceiling.json"
    document = {"sensors": {"RGB": {
        "intrinsics": {"type_id": "opencv-matrix", "rows": 3, "cols": 3, "dt": "d", "data": K_GOPRO.ravel().tolist()},
        "distortionCoefficients": {"type_id": "opencv-matrix", "rows": 1, "cols": 5, "dt": "d",
                                   "data": DIST_GOPRO.tolist()},
    }}}
    path.write_text(json.dumps(document))
    read = read_intrinsics(path)
    assert read.name == "ceiling" and read.resolution is None
    np.testing.assert_array_equal(read.K, K_GOPRO)
    np.testing.assert_array_equal(read.dist, DIST_GOPRO)


def test_directory_of_mixed_formats(tmp_path):
    write_intrinsics(tmp_path / "far1.json", gopro())
    storage = cv2.FileStorage(str(tmp_path / "far2.yaml"), cv2.FILE_STORAGE_WRITE)
    storage.write("camera_matrix", K_GOPRO)
    storage.write("distortion_coefficients", DIST_GOPRO)
    storage.release()
    (tmp_path / "notes.txt").write_text("not intrinsics")
    cameras = load_intrinsics_dir(tmp_path)
    assert sorted(cameras) == ["far1", "far2"]
    assert cameras["far2"].name == "far2" and cameras["far2"].resolution is None


def test_directory_errors(tmp_path):
    with pytest.raises(ValueError, match="no such intrinsics directory"):
        load_intrinsics_dir(tmp_path / "missing")
    with pytest.raises(ValueError, match="no intrinsics files"):
        load_intrinsics_dir(tmp_path)
    write_intrinsics(tmp_path / "far1.json", gopro())
    storage = cv2.FileStorage(str(tmp_path / "far1.yaml"), cv2.FILE_STORAGE_WRITE)
    storage.write("camera_matrix", K_GOPRO)
    storage.write("distortion_coefficients", DIST_GOPRO)
    storage.release()
    with pytest.raises(ValueError, match=r"far1\.(json|yaml): a second intrinsics file for camera 'far1'"):
        load_intrinsics_dir(tmp_path)


@pytest.mark.parametrize(("content", "message"), [
    ("{not json", "not valid JSON"),
    ('{"schema": "calibproj.intrinsics/1", "resolution": [1920, 1080]}', "missing field 'K'"),
    ('{"schema": "calibproj.intrinsics/1", "resolution": [1920, 1080], "K": [1, 2, 3]}', "K must have 9 values"),
    ('{"schema": "calibproj.intrinsics/1", "resolution": [1920, 1080], "K": [[900, 0, 960], [0, 900, 540], '
     '[0, 0, 1]], "dist": [0.1, 0.2, 0.3]}', "dist must have 4, 5, 8, 12, 14 coefficients, got 3"),
    ('{"schema": "calibproj.intrinsics/1", "resolution": [1920, 1080], "K": [[900, 1, 960], [0, 900, 540], '
     '[0, 0, 1]]}', r"K must be \[\[fx, 0, cx\]"),
    ('{"schema": "calibproj.intrinsics/1", "resolution": [1920, -3], "K": [[900, 0, 960], [0, 900, 540], '
     '[0, 0, 1]]}', "resolution must be two positive integers"),
    ('{"schema": "calibproj.intrinsics/2", "resolution": [1920, 1080]}', "newer than this calibproj reads"),
    ('{"sensors": {"RGB": {"intrinsics": {}}}}', "expected sensors.RGB.intrinsics.data"),
    # true and false are no numbers (they were read as 1.0 and 0.0).
    ('{"schema": "calibproj.intrinsics/1", "resolution": [1920, 1080], "K": [[true, 0, 960], [0, 900, 540], '
     '[0, 0, 1]]}', "K: expected numbers, got true"),
    ('{"schema": "calibproj.intrinsics/1", "resolution": [1920, 1080], "K": [[900, 0, 960], [0, 900, 540], '
     '[0, 0, 1]], "dist": [false, 0, 0, 0, 0]}', "dist: expected numbers, got false"),
    ('{"schema": "calibproj.intrinsics/1", "resolution": [true, 1080], "K": [[900, 0, 960], [0, 900, 540], '
     '[0, 0, 1]]}', r"resolution must be two positive integers \[width, height\], got \[true, 1080\]"),
    ('{"schema": "calibproj.intrinsics/1", "resolution": [1920, 1080], "K": [["900", 0, 960], [0, 900, 540], '
     '[0, 0, 1]]}', 'K: expected numbers, got "900"'),
    ('{"sensors": {"RGB": {"intrinsics": {"data": [900, 0, 960, 0, 900, 540, 0, 0, true]}, '
     '"distortionCoefficients": {"data": [0, 0, 0, 0, 0]}}}}', "K: expected numbers, got true"),
    # NaN and infinities are no JSON, and a resolution past what the core takes is refused.
    ('{"schema": "calibproj.intrinsics/1", "resolution": [1920, 1080], "K": [[NaN, 0, 960], [0, 900, 540], '
     '[0, 0, 1]]}', r"not valid JSON \(NaN is not a JSON number\)"),
    ('{"schema": "calibproj.intrinsics/1", "resolution": [1920, 1080], "K": [[1e400, 0, 960], [0, 900, 540], '
     '[0, 0, 1]]}', "number 1e400 is beyond the range of a double"),
    ('{"schema": "calibproj.intrinsics/1", "resolution": [1e300, 1080], "K": [[900, 0, 960], [0, 900, 540], '
     '[0, 0, 1]]}', "image size must be at most 65536 pixels per side"),
    ('{"schema": "calibproj.intrinsics/1", "resolution": [1920, 1080], "K": ' + "[" * 600 + "]" * 600 + "}",
     "nested deeper than 512 levels"),
])
def test_malformed_files_name_the_file_and_problem(tmp_path, content, message):
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(ValueError, match=message) as error:
        read_intrinsics(path)
    assert str(path) in str(error.value)


def test_missing_and_unknown_files(tmp_path):
    with pytest.raises(ValueError, match="no such intrinsics file"):
        read_intrinsics(tmp_path / "absent.json")
    (tmp_path / "cam.txt").write_text("")
    with pytest.raises(ValueError, match="unknown intrinsics format"):
        read_intrinsics(tmp_path / "cam.txt")
    storage = cv2.FileStorage(str(tmp_path / "cam.yaml"), cv2.FILE_STORAGE_WRITE)
    storage.write("distortion_coefficients", DIST_GOPRO)
    storage.release()
    with pytest.raises(ValueError, match=r"cam\.yaml: missing camera_matrix"):
        read_intrinsics(tmp_path / "cam.yaml")
    (tmp_path / "broken.yaml").write_text("camera_matrix: [1, 2\n  : :")
    with pytest.raises(ValueError, match=r"broken\.yaml: not a readable OpenCV YAML/XML file"):
        read_intrinsics(tmp_path / "broken.yaml")


def test_each_camera_gets_its_own_file_or_its_own_reason(tmp_path):
    """A bad, missing or doubled file fails its own camera only; the reason names the file."""
    write_intrinsics(tmp_path / "far1.json", gopro())
    (tmp_path / "far2.json").write_text('{"schema": "calibproj.intrinsics/1", "resolution": [1920, 1080], '
                                        '"K": [[true, 0, 960], [0, 900, 540], [0, 0, 1]]}')
    write_intrinsics(tmp_path / "far3.json", gopro())
    (tmp_path / "far3.yml").write_text("%YAML:1.0\n")
    (tmp_path / "unused.json").write_text("{broken")  # a camera nobody asks for is not read
    cameras, unusable = intrinsics_of_cameras(tmp_path, ["far1", "far2", "far3", "far4"])
    assert sorted(cameras) == ["far1"] and cameras["far1"].name == "far1"
    assert unusable == {
        "far2": f"{tmp_path / 'far2.json'}: K: expected numbers, got true",
        "far3": f"{tmp_path / 'far3.yml'}: a second intrinsics file for camera 'far3'",
        "far4": f"{tmp_path / 'far4.json'}: no intrinsics file for camera 'far4' (also looked for far4.yaml, "
                "far4.yml, far4.xml)",
    }
    with pytest.raises(ValueError, match=r"far2\.json: K: expected numbers"):
        load_intrinsics_dir(tmp_path)  # every file, strictly
    given = {"far1": cameras["far1"]}
    assert intrinsics_of_cameras(given, ["far1", "far5"]) == (
        given, {"far5": "no intrinsics for camera 'far5' (cameras with intrinsics: far1)"})
    with pytest.raises(ValueError, match="no such intrinsics directory"):
        intrinsics_of_cameras(tmp_path / "missing", ["far1"])
