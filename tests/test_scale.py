"""Metric scale from one measurement: parsing, the three kinds, and the command line."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from calibproj.cli.main import main
from calibproj.registration.driver import register
from calibproj.scale.metric import apply_scale, check_measurement, parse_scale, scale_factor, scaled
from calibproj.sequence.projected import ProjectedMarkers, layout_markers
from calibproj.simulate import simulate_tracks
from calibproj.simulate.scene import Projector, load_scene

# After scaling, camera centres must match the truth up to a rigid motion within this
# (the paper rig is about 5.6 m across; 0.5 px noise leaves about 1 mm).
MAX_CENTRE_ERROR_M = 0.005
# Relative error of a scale factor estimated from one marker's neighbourhood.
MAX_MARKER_SCALE_ERROR = 0.003


@pytest.fixture(scope="module")
def paper():
    sim = simulate_tracks("paper", None, noise_px=0.5, seed=3)
    return sim, register(sim.tracks, sim.intrinsics)


def rigid_centre_errors(calibration, scene) -> np.ndarray:
    """Centre errors after the best rigid (rotation + translation, no scale) alignment."""
    names = calibration.registered
    estimate = np.array([calibration.center(name) for name in names])
    truth = np.array([scene.camera(name).center for name in names])
    estimate_mean, truth_mean = estimate.mean(axis=0), truth.mean(axis=0)
    U, _, Vt = np.linalg.svd((truth - truth_mean).T @ (estimate - estimate_mean))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    return np.linalg.norm((estimate - estimate_mean) @ R.T + truth_mean - truth, axis=1)


def true_marker_side(scene, markers: ProjectedMarkers, pixel: np.ndarray) -> float:
    half = markers.marker_side_px / 2.0
    square = pixel + half * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    corners = scene.projector.pixels_to_floor(square)
    return float(np.mean(np.linalg.norm(corners - np.roll(corners, -1, axis=0), axis=1)))


# -- parsing -------------------------------------------------------------------------------


def test_parse_every_kind() -> None:
    height = parse_scale("camera-height:far1=2.8")
    assert (height.kind, height.cameras, height.metres) == ("camera-height", ("far1",), 2.8)
    distance = parse_scale("distance:far1, near2=3.25")
    assert (distance.kind, distance.cameras, distance.metres) == ("distance", ("far1", "near2"), 3.25)
    marker = parse_scale("marker-size:0.05")
    assert (marker.kind, marker.marker, marker.metres) == ("marker-size", None, 0.05)
    assert parse_scale("marker-size:12/5=0.048").marker == (12, 5)


@pytest.mark.parametrize(
    "text, message",
    [
        ("camera-height", "expected camera-height:NAME=METRES"),
        ("height:far1=2", "unknown kind 'height'"),
        ("camera-height:far1=two", "'two' is not a length in metres"),
        ("camera-height:far1=-2", "positive number of metres"),
        ("camera-height:far1=nan", "positive number of metres"),
        ("camera-height:=2", "no camera name"),
        ("distance:far1=3", "expected two cameras CAM_A,CAM_B"),
        ("distance:far1,far2", "expected distance:CAM_A,CAM_B=METRES"),
        ("distance:far1,far1=3", "two different cameras"),
        ("marker-size:12-5=0.05", "ARRAY/MARKER"),
        ("marker-size:0", "positive number of metres"),
    ],
)
def test_parse_errors_name_the_bad_part(text: str, message: str) -> None:
    with pytest.raises(ValueError, match="scale measurement") as error:
        parse_scale(text)
    assert message in str(error.value)


# -- the three kinds -----------------------------------------------------------------------


def test_camera_height_gives_metric_poses(paper) -> None:
    sim, calibration = paper
    metric = apply_scale(calibration, f"camera-height:far2={sim.scene.camera('far2').center[2]}")
    assert metric.unit == "m"
    assert rigid_centre_errors(metric, sim.scene).max() < MAX_CENTRE_ERROR_M


def test_distance_gives_metric_poses(paper) -> None:
    sim, calibration = paper
    length = np.linalg.norm(sim.scene.camera("far1").center - sim.scene.camera("near3").center)
    metric = apply_scale(calibration, f"distance:far1,near3={length}")
    assert rigid_centre_errors(metric, sim.scene).max() < MAX_CENTRE_ERROR_M


def test_marker_size_at_the_image_centre_gives_metric_poses(paper) -> None:
    sim, calibration = paper
    markers = layout_markers(sim.layout)
    side = true_marker_side(sim.scene, markers, markers.image_centre())
    metric = apply_scale(calibration, f"marker-size:{side}", markers)
    assert rigid_centre_errors(metric, sim.scene).max() < MAX_CENTRE_ERROR_M
    # Still on the floor, now in metres: on the floor's fitted relief, which the noise
    # moves by a fraction of a millimetre here.
    assert np.abs(metric.points[:, 2]).max() < 2e-3


def test_marker_size_is_local_under_a_tilted_projector() -> None:
    """A tilted projector draws markers of different sizes across the floor; the scale must
    come from the neighbourhood of the marker measured, not from the image centre."""
    scene = load_scene("paper", seed=5)
    tilted = Projector(position=(0.9, -0.4, 3.0), look_at=(0.0, 0.0, 0.0), resolution=(1920, 1080), fx=1400.0)
    sim = simulate_tracks(dataclasses.replace(scene, projector=tilted), None, noise_px=0.5, seed=5)
    calibration = register(sim.tracks, sim.intrinsics)
    markers = layout_markers(sim.layout)
    pixels = markers.pixels(calibration.point_ids)
    chosen = calibration.point_ids[np.argmin(np.linalg.norm(pixels - [600.0, 350.0], axis=1))]
    array, marker = divmod(int(chosen), markers.markers_per_array)
    side = true_marker_side(sim.scene, markers, markers.pixels([chosen])[0])
    centre_side = true_marker_side(sim.scene, markers, markers.image_centre())
    assert abs(side / centre_side - 1.0) > 0.02  # the test means something
    metric = apply_scale(calibration, f"marker-size:{array}/{marker}={side}", markers)
    truth = np.linalg.norm(sim.scene.camera("far1").center - sim.scene.camera("far4").center)
    measured = np.linalg.norm(metric.center("far1") - metric.center("far4"))
    assert measured / truth == pytest.approx(1.0, abs=MAX_MARKER_SCALE_ERROR)
    assert rigid_centre_errors(metric, sim.scene).max() < MAX_CENTRE_ERROR_M


def test_scaled_multiplies_lengths_only(paper) -> None:
    _, calibration = paper
    metric = scaled(calibration, 2.5)
    name = calibration.registered[0]
    np.testing.assert_array_equal(metric.poses[name][0], calibration.poses[name][0])
    np.testing.assert_allclose(metric.poses[name][1], 2.5 * calibration.poses[name][1])
    np.testing.assert_allclose(metric.center(name), 2.5 * calibration.center(name))
    np.testing.assert_allclose(metric.points, 2.5 * calibration.points)
    assert metric.floor_rms == pytest.approx(2.5 * calibration.floor_rms)
    assert calibration.unit == "arbitrary" and metric.unit == "m"  # the original is left alone


# -- errors --------------------------------------------------------------------------------


def test_measurements_that_cannot_apply_name_the_problem(paper) -> None:
    sim, calibration = paper
    markers = layout_markers(sim.layout)
    with pytest.raises(ValueError, match="no camera 'far9'"):
        check_measurement(parse_scale("camera-height:far9=2"), sim.tracks.camera_names)
    with pytest.raises(ValueError, match="needs the projection sequence"):
        scale_factor(calibration, "marker-size:0.05")
    with pytest.raises(ValueError, match="no marker 100/0 in the sequence"):
        check_measurement(parse_scale("marker-size:100/0=0.05"), sim.tracks.camera_names, markers)
    failed = calibration.replace(poses={k: v for k, v in calibration.poses.items() if k != "far2"},
                                 failed={"far2": "too few points"})
    with pytest.raises(ValueError, match=r"camera 'far2' failed to register \(too few points\)"):
        scale_factor(failed, "distance:far1,far2=3")
    sparse = calibration.replace(points=calibration.points[:5], point_ids=calibration.point_ids[:5])
    with pytest.raises(ValueError, match="measure a marker that the cameras saw"):
        scale_factor(sparse, "marker-size:0.05", markers)


# -- command line --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_simulation(tmp_path_factory):
    out = tmp_path_factory.mktemp("small")
    simulate_tracks("small", out, noise_px=0.3, seed=2)
    return out


def calibrate_args(sim_dir, out, *extra: str) -> list[str]:
    return ["calibrate", "--tracks", str(sim_dir / "tracks.json"), "--intrinsics", str(sim_dir / "intrinsics"),
            "--out", str(out), "--no-report", *extra]


def test_cli_scale_writes_metric_results(small_simulation, tmp_path, capsys) -> None:
    from calibproj.formats.calibration import Calibration
    from calibproj.formats.poses import read_poses

    truth = read_poses(small_simulation / "truth.json")
    height = truth.center("cam1")[2]
    assert main(calibrate_args(small_simulation, tmp_path / "r", "--scale", f"camera-height:cam1={height}")) == 0
    assert capsys.readouterr().out.splitlines()[-1] == f"results: {tmp_path / 'r'} (in metres)"
    result = Calibration.load(tmp_path / "r")
    assert result.unit == "m"
    assert result.center("cam1")[2] == pytest.approx(height, rel=1e-9)


@pytest.mark.parametrize(
    "scale, message",
    [
        ("camera-height:cam1", "expected camera-height:NAME=METRES"),
        ("cam-height:cam1=2", "unknown kind"),
        ("camera-height:nobody=2", "no camera 'nobody'"),
        ("marker-size:0.05", "marker-size needs --sequence"),
    ],
)
def test_cli_bad_scale_exits_with_one_line(small_simulation, tmp_path, capsys, scale: str, message: str) -> None:
    assert main(calibrate_args(small_simulation, tmp_path / "r", "--scale", scale)) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and message in error
    assert not (tmp_path / "r" / "camera_poses.json").exists()


def test_projector_pixels_follow_the_point_ids() -> None:
    from calibproj import _core

    centres = np.arange(2 * 3 * 2, dtype=float).reshape(2, 3, 2) + 0.5  # 2 arrays of 3 markers
    markers = ProjectedMarkers(centres, 24.0, (1920, 1080))
    pixels = markers.pixels(np.array([4, 0, 6, -1], dtype=np.int64))
    np.testing.assert_array_equal(pixels[:2], [centres[1, 1], centres[0, 0]])  # id = array * 3 + marker
    assert np.isnan(pixels[2:]).all()  # beyond the sequence's MSMs
