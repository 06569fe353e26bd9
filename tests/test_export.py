"""Exports read back with the readers of their tools' formats: cv2.FileStorage, COLMAP's
text layout, tomllib."""

from __future__ import annotations

import tomllib

import cv2
import numpy as np
import pytest

from calibproj.cli.main import main
from calibproj.formats.export import colmap_camera, export, export_all, parse_formats, quaternion_wxyz
from calibproj.formats.intrinsics import Intrinsics
from calibproj.registration.driver import register
from calibproj.scale.metric import apply_scale
from calibproj.simulate import simulate_tracks


@pytest.fixture(scope="module")
def small():
    """Three cameras: cam1 and cam3 without distortion, cam2 with k1 and k2."""
    sim = simulate_tracks("small", None, noise_px=0.3, seed=1)
    calibration = register(sim.tracks, sim.intrinsics)
    metric = apply_scale(calibration, f"camera-height:cam1={sim.scene.camera('cam1').center[2]}")
    return sim, metric


@pytest.fixture(scope="module")
def exported(small, tmp_path_factory):
    sim, calibration = small
    out = tmp_path_factory.mktemp("export")
    export_all(calibration, ["yaml", "colmap", "anipose"], out, sim.intrinsics, sim.tracks)
    return out


def rotation_from_quaternion(w: float, x: float, y: float, z: float) -> np.ndarray:
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def data_lines(path) -> list[str]:
    return [line for line in path.read_text().splitlines() if not line.startswith("#")]


# -- OpenCV YAML ---------------------------------------------------------------------------


def test_yaml_reads_back_with_filestorage(small, exported) -> None:
    sim, calibration = small
    storage = cv2.FileStorage(str(exported / "calibration_opencv.yaml"), cv2.FILE_STORAGE_READ)
    assert storage.getNode("schema").string() == "calibproj.opencv_calibration/1"
    assert storage.getNode("unit").string() == "m"
    cameras = storage.getNode("cameras")
    assert cameras.size() == int(storage.getNode("camera_count").real()) == len(calibration.poses)
    for index, name in enumerate(calibration.poses):
        node = cameras.at(index)
        R, t = calibration.poses[name]
        assert node.getNode("name").string() == name
        np.testing.assert_array_equal(node.getNode("camera_matrix").mat(), sim.intrinsics[name].K)
        np.testing.assert_array_equal(node.getNode("distortion_coefficients").mat().ravel(), sim.intrinsics[name].dist)
        np.testing.assert_array_equal(node.getNode("R").mat(), R)
        np.testing.assert_array_equal(node.getNode("t").mat().ravel(), t)
        np.testing.assert_allclose(cv2.Rodrigues(node.getNode("rvec").mat())[0], R, atol=1e-12)
        size = (int(node.getNode("image_width").real()), int(node.getNode("image_height").real()))
        assert size == sim.intrinsics[name].resolution
        # How well the camera is known travels with it (the reference has no sigma of its own).
        status, metrics = node.getNode("status").string(), calibration.metrics[name]
        assert status == expected_status(calibration, name)
        assert node.getNode("mean_error_px").real() == pytest.approx(metrics.mean_px)
        if status != "reference":
            assert node.getNode("rotation_sigma_deg").real() == pytest.approx(metrics.rotation_sigma_deg)
            assert node.getNode("centre_sigma").real() == pytest.approx(metrics.centre_sigma)
        else:
            assert node.getNode("rotation_sigma_deg").empty()
    storage.release()


def expected_status(calibration, name: str) -> str:
    if calibration.registration_order[0] == name:
        return "reference"
    return "weak" if calibration.metrics[name].weak else "ok"


# -- COLMAP --------------------------------------------------------------------------------


def read_colmap(folder):
    cameras = {}
    for line in data_lines(folder / "cameras.txt"):
        camera_id, model, width, height, *params = line.split()
        cameras[int(camera_id)] = (model, int(width), int(height), np.array(params, dtype=float))
    images = {}
    lines = data_lines(folder / "images.txt")
    for header, points in zip(lines[0::2], lines[1::2]):
        image_id, qw, qx, qy, qz, tx, ty, tz, camera_id, name = header.split()
        values = np.array(points.split(), dtype=float).reshape(-1, 3)
        images[int(image_id)] = {
            "name": name, "camera_id": int(camera_id), "R": rotation_from_quaternion(*map(float, (qw, qx, qy, qz))),
            "q": np.array([qw, qx, qy, qz], dtype=float), "t": np.array([tx, ty, tz], dtype=float),
            "xy": values[:, :2], "point_ids": values[:, 2].astype(np.int64),
        }
    points = {}
    for line in data_lines(folder / "points3D.txt"):
        fields = line.split()
        track = np.array(fields[8:], dtype=np.int64).reshape(-1, 2)
        points[int(fields[0])] = {"xyz": np.array(fields[1:4], dtype=float), "error": float(fields[7]), "track": track}
    return cameras, images, points


def test_colmap_model_parses_and_matches(small, exported) -> None:
    sim, calibration = small
    cameras, images, points = read_colmap(exported / "colmap")
    assert [image["name"] for image in images.values()] == list(calibration.poses)
    for image in images.values():
        name = image["name"]
        R, t = calibration.poses[name]
        np.testing.assert_allclose(image["R"], R, atol=1e-12)
        np.testing.assert_array_equal(image["t"], t)
        assert image["q"][0] >= 0 and np.linalg.norm(image["q"]) == pytest.approx(1.0)
        model, width, height, params = cameras[image["camera_id"]]
        intrinsics = sim.intrinsics[name]
        assert (width, height) == intrinsics.resolution
        assert model == ("OPENCV" if intrinsics.has_distortion else "PINHOLE")
        np.testing.assert_allclose(params[:4], [intrinsics.K[0, 0], intrinsics.K[1, 1],
                                                intrinsics.K[0, 2] + 0.5, intrinsics.K[1, 2] + 0.5])
        # 2D points: the tracks' observations, distorted and in COLMAP's pixel convention.
        ids, xy = sim.tracks.observations(name)
        lookup = dict(zip(ids.tolist(), xy))
        expected = np.array([lookup[i] for i in image["point_ids"]])
        np.testing.assert_allclose(intrinsics.undistort_points(image["xy"] - 0.5), expected, atol=1e-6)
    assert sorted(points) == sorted(calibration.point_ids.tolist())
    by_id = dict(zip(calibration.point_ids.tolist(), calibration.points))
    for point_id, point in points.items():
        np.testing.assert_array_equal(point["xyz"], by_id[point_id])
        for image_id, index in point["track"]:
            assert images[image_id]["point_ids"][index] == point_id
    assert np.median([p["error"] for p in points.values()]) < 1.0
    # COLMAP skips comments: each camera's status and sigmas are in cameras.txt's.
    comments = [line for line in (exported / "colmap" / "cameras.txt").read_text().splitlines()
                if line.startswith("# calibproj camera ")]
    assert len(comments) == len(calibration.poses)
    for line, name in zip(comments, calibration.poses):
        assert line.split(": ", 1)[1].startswith(f"{name} {expected_status(calibration, name)}")
        assert (" deg, centre " in line) == (expected_status(calibration, name) != "reference")


def test_colmap_camera_models() -> None:
    K = [[900.0, 0.0, 640.0], [0.0, 905.0, 360.0], [0.0, 0.0, 1.0]]
    model, params = colmap_camera(Intrinsics("a", (1280, 720), K, [0.0, 0.0, 0.0, 0.0, 0.0]))
    assert (model, params) == ("PINHOLE", [900.0, 905.0, 640.5, 360.5])
    model, params = colmap_camera(Intrinsics("b", (1280, 720), K, [-0.1, 0.02, 0.001, 0.0, 0.003]))
    assert model == "FULL_OPENCV" and params[4:] == pytest.approx([-0.1, 0.02, 0.001, 0.0, 0.003, 0, 0, 0])
    with pytest.raises(ValueError, match="camera c: thin-prism or tilt"):
        colmap_camera(Intrinsics("c", (1280, 720), K, [0.0] * 8 + [0.01, 0.0, 0.0, 0.0]))


def test_quaternion_convention() -> None:
    angle = np.radians(30.0)
    about_z = np.array([[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(quaternion_wxyz(about_z), [np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2)])


# -- aniposelib TOML -----------------------------------------------------------------------


def test_anipose_toml_loads_with_the_same_values(small, exported) -> None:
    sim, calibration = small
    with open(exported / "calibration.toml", "rb") as handle:
        document = tomllib.load(handle)
    assert set(document) == {f"cam_{i}" for i in range(len(calibration.poses))} | {"metadata"}
    for index, name in enumerate(calibration.poses):
        camera = document[f"cam_{index}"]
        R, t = calibration.poses[name]
        assert camera["name"] == name
        assert tuple(camera["size"]) == sim.intrinsics[name].resolution
        np.testing.assert_array_equal(camera["matrix"], sim.intrinsics[name].K)
        np.testing.assert_array_equal(camera["distortions"], sim.intrinsics[name].dist)
        np.testing.assert_allclose(cv2.Rodrigues(np.array(camera["rotation"]))[0], R, atol=1e-12)
        np.testing.assert_array_equal(camera["translation"], t)
        assert camera["status"] == expected_status(calibration, name)
        if camera["status"] != "reference":
            assert camera["rotation_sigma_deg"] == pytest.approx(calibration.metrics[name].rotation_sigma_deg)
    metadata = document["metadata"]
    assert metadata["unit"] == "m" and 0.0 < metadata["error"] < 1.0


# -- errors and command line ---------------------------------------------------------------


def test_bad_formats_are_named(small, tmp_path) -> None:
    sim, calibration = small
    assert parse_formats("yaml, colmap,yaml") == ["yaml", "colmap"]
    with pytest.raises(ValueError, match="export format 'ply' unknown"):
        parse_formats("yaml,ply")
    with pytest.raises(ValueError, match="export format 'ply' unknown"):
        export(calibration, "ply", tmp_path, sim.intrinsics)
    with pytest.raises(ValueError, match="no intrinsics for registered camera"):
        export(calibration, "yaml", tmp_path, {})


def test_cli_export_writes_every_format(tmp_path, capsys) -> None:
    sim_dir = tmp_path / "sim"
    simulate_tracks("small", sim_dir, noise_px=0.3, seed=1)
    arguments = ["calibrate", "--tracks", str(sim_dir / "tracks.json"), "--intrinsics", str(sim_dir / "intrinsics"),
                 "--out", str(tmp_path / "r"), "--no-report"]
    assert main([*arguments, "--export", "yaml,colmap,anipose"]) == 0
    for name in ("calibration_opencv.yaml", "colmap/cameras.txt", "colmap/images.txt", "colmap/points3D.txt",
                 "calibration.toml"):
        assert (tmp_path / "r" / name).is_file(), name
    assert not (tmp_path / "r" / "report.html").exists()
    capsys.readouterr()
    assert main([*arguments, "--force", "--export", "yaml,fbx"]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "export format 'fbx' unknown" in error
