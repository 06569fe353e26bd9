"""Calibration is the core's type: a value, read and written by the same C++ as
calibproj-native, that keeps its checks when changed from Python."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

from calibproj import _core
from calibproj.formats.calibration import Calibration, CameraMetrics, Plane
from calibproj.simulate.synthetic import matrix_from_rotvec


def two_cameras() -> Calibration:
    poses = {"b": (matrix_from_rotvec([0.1, 0.0, 0.0]), np.array([0.0, 0.0, 2.0])),
             "a": (np.eye(3), np.array([1.0, 0.0, 2.0]))}
    metrics = {"b": CameraMetrics(0.2, 0.1, 20, 19, 18, 90, rotation_sigma_deg=0.0, centre_sigma=0.0),
               "a": CameraMetrics(0.3, 0.1, 20, 18, 18, 80, rotation_sigma_deg=0.08, centre_sigma=0.01, weak=True),
               "c": CameraMetrics(None, None, 5, 0, 0, 0, failure="too few points")}
    points = np.arange(12, dtype=float).reshape(4, 3)
    return Calibration(poses, {"c": "too few points"}, metrics, points, np.array([7, 3, 9, 1]),
                       registration_order=["b", "a"], planes=[Plane([0.0, 0.0, 1.0], 0.9, 2)])


def test_the_calibration_keeps_order_and_answers_per_camera() -> None:
    calibration = two_cameras()
    assert calibration.registered == ["b", "a"] and list(calibration.poses) == ["b", "a"]
    assert [calibration.status(name) for name in "abc"] == ["weak", "reference", "failed"]
    R, t = calibration.poses["b"]
    np.testing.assert_allclose(calibration.center("b"), -R.T @ t)
    np.testing.assert_allclose(calibration.pose("a").t, [1.0, 0.0, 2.0])
    with pytest.raises(ValueError, match="camera c: not registered"):
        calibration.center("c")
    assert calibration.metrics["c"].failure == "too few points" and calibration.failed == {"c": "too few points"}
    assert calibration.planes[0].offset == 0.9 and calibration.planes[0].points == 2


def test_its_arrays_are_copies_that_cannot_be_written() -> None:
    calibration = two_cameras()
    for array in (calibration.points, calibration.point_ids, *calibration.poses["a"]):
        with pytest.raises(ValueError, match="read-only"):
            array[0] = 0
    metrics = calibration.metrics
    metrics["b"].weak = True  # a copy: the calibration is unchanged until it is given back
    assert calibration.status("b") == "reference" and not calibration.metrics["b"].weak
    calibration.metrics = metrics
    assert calibration.metrics["b"].weak


def test_replace_copies_and_checks() -> None:
    calibration = two_cameras()
    metric = calibration.replace(unit="m", points=calibration.points[:2], point_ids=[7, 3])
    assert metric.unit == "m" and len(metric.points) == 2 and calibration.unit == "arbitrary"
    with pytest.raises(ValueError):
        calibration.replace(points=calibration.points[:2])  # 2 points, 4 ids
    with pytest.raises(ValueError):
        calibration.replace(unit="furlong")
    with pytest.raises(TypeError, match="no attribute colour"):
        calibration.replace(colour="red")
    with pytest.raises(TypeError, match="Calibration.poses"):
        calibration.replace(poses={"a": "not a pose"})
    # The poses of a camera_poses.json are named as such.
    with pytest.raises(TypeError, match="^CameraPoses.poses: "):
        _core.formats.CameraPoses({"a": "not a pose"})
    with pytest.raises(TypeError, match="^CameraPoses.failed: "):
        _core.formats.CameraPoses({}, failed={"b": 3})
    with pytest.raises(ValueError, match="expected shape"):
        calibration.replace(points=np.zeros((4, 2)))


def test_copies_pickles_and_files_are_the_same_calibration(tmp_path) -> None:
    calibration = two_cameras()
    for other in (copy.copy(calibration), copy.deepcopy(calibration), pickle.loads(pickle.dumps(calibration))):
        assert other is not calibration
        assert list(other.poses) == list(calibration.poses) and other.metrics == calibration.metrics
        np.testing.assert_array_equal(other.points, calibration.points)
    calibration.save(tmp_path)
    loaded = Calibration.load(tmp_path)
    assert loaded.metrics == calibration.metrics and loaded.registration_order == ["b", "a"]
    np.testing.assert_allclose(loaded.poses["b"][0], calibration.poses["b"][0], atol=1e-12)
    with pytest.raises(_core.formats.InputError, match="no such results folder"):
        Calibration.load(tmp_path / "missing")


def test_nothing_registered_lists_every_camera_as_failed() -> None:
    empty = Calibration.nothing_registered({"a": "no intrinsics file", "b": "no video"}, "free")
    assert empty.registered == [] and empty.model == "free" and empty.points.shape == (0, 3)
    assert {name: m.failure for name, m in empty.metrics.items()} == {"a": "no intrinsics file", "b": "no video"}


def test_metrics_refuse_what_metrics_json_cannot_hold() -> None:
    with pytest.raises(ValueError, match="rotation_sigma_deg"):
        CameraMetrics(0.1, 0.1, 1, 1, 1, 1, rotation_sigma_deg=float("nan"))
    with pytest.raises(ValueError, match="counts"):
        CameraMetrics(0.1, 0.1, -1, 1, 1, 1)
