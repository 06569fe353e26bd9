"""Geometric simulation: visibility, exact noise-free geometry, noise and outlier statistics, CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calibproj.cli.main import main
from calibproj.sequence.layout import MsmLayout
from calibproj.formats.intrinsics import load_intrinsics_dir
from calibproj.formats.poses import read_poses
from calibproj.simulate.geometric import project_points, simulate_tracks
from calibproj.simulate.scene import load_scene, read_scene
from calibproj.formats.tracks import Tracks


@pytest.fixture(scope="module")
def paper_clean():
    return simulate_tracks("paper", noise_px=0.0, seed=0)


@pytest.fixture(scope="module")
def or_full_clean():
    return simulate_tracks("or-full", noise_px=0.0, seed=0)


def reprojection_residuals(simulation, tracks: Tracks, points: np.ndarray) -> np.ndarray:
    """Observed minus pinhole projection of the true points, with the true poses."""
    residuals = np.empty_like(tracks.xy)
    for index, camera in enumerate(simulation.scene.cameras):
        rows = tracks.camera_index == index
        in_camera = points[tracks.observation_ids()[rows]] @ camera.R.T + camera.t
        projected = (in_camera / in_camera[:, 2:]) @ camera.K.T
        residuals[rows] = tracks.xy[rows] - projected[:, :2]
    return residuals


def test_every_paper_camera_sees_a_good_share_of_the_grid(paper_clean):
    counts = paper_clean.tracks.counts_per_camera()
    # Seed 0: the far cameras decode all 3200 MSMs; the near ones, 1.8 m from the
    # centre, 2446-2952 (their images do not hold the whole projected area).
    assert paper_clean.tracks.num_points == 3200
    assert all(counts[f"far{i}"] == 3200 for i in range(1, 7))
    assert all(2000 <= counts[f"near{i}"] < 3200 for i in range(1, 5))


def test_or_full_close_up_camera_sees_some_tens_of_msms(or_full_clean):
    counts = or_full_clean.tracks.counts_per_camera()
    # The 11,100 px camera frames about 0.5 x 0.3 m of floor: 58 MSM centres; the
    # lamp cameras decode 2876 and 2807, the far-field GoPros all 3200.
    assert 20 <= counts["ceiling"] <= 100
    assert min(counts[f"far{i}"] for i in range(1, 7)) == 3200
    assert counts["near1"] > 2000 and counts["near2"] > 2000
    pairs = or_full_clean.tracks.pair_counts_by_name()
    assert pairs[("near1", "ceiling")] == counts["ceiling"]


def test_noise_free_observations_reproject_exactly_through_truth(or_full_clean, tmp_path):
    or_full_clean.write(tmp_path)
    truth = json.loads((tmp_path / "truth.json").read_text())
    points = np.array(truth["points"]["xyz"])
    assert truth["points"]["ids"] == list(range(3200))
    tracks = Tracks.read(tmp_path / "tracks.json")
    assert np.abs(reprojection_residuals(or_full_clean, tracks, points)).max() < 1e-8
    np.testing.assert_allclose(points[:, 2], 0.0, atol=1e-12)
    eval_points = np.array(truth["eval_points"]["xyz"])
    eval_tracks = Tracks.read(tmp_path / "eval_tracks.json")
    assert np.abs(reprojection_residuals(or_full_clean, eval_tracks, eval_points)).max() < 1e-8
    poses = read_poses(tmp_path / "truth.json")
    assert poses.unit == "m" and poses.names == or_full_clean.scene.camera_names
    for camera in or_full_clean.scene.cameras:
        np.testing.assert_allclose(poses.center(camera.name), camera.position, atol=1e-12)


def test_msm_centres_sit_on_the_layout_grid_through_the_projector(or_full_clean):
    scene, layout = or_full_clean.scene, or_full_clean.layout
    projector = scene.projector
    in_projector = or_full_clean.msm_points @ projector.R.T + projector.t
    pixels = (in_projector / in_projector[:, 2:]) @ projector.K.T
    np.testing.assert_allclose(pixels[:, :2], layout.centres().reshape(-1, 2), atol=1e-8)


def test_observations_are_inside_the_distorted_image(or_full_clean):
    tracks = or_full_clean.tracks
    for index, camera in enumerate(or_full_clean.scene.cameras):
        distorted = camera.intrinsics.distort_points(tracks.xy[tracks.camera_index == index])
        assert camera.intrinsics.contains(distorted).all()


def test_marker_size_rule():
    scene = load_scene("or-full")
    strict = simulate_tracks(scene, min_marker_px=60.0, eval_points=0, eval_points_per_camera=0)
    default = simulate_tracks(scene, eval_points=0, eval_points_per_camera=0)
    for name in scene.camera_names:
        assert strict.tracks.counts_per_camera()[name] <= default.tracks.counts_per_camera()[name]
    assert strict.tracks.counts_per_camera()["far1"] < 3200
    # One scale of 8 projector pixels (1.7 cm on the floor): below 15 px in the far-field cameras.
    tiny = MsmLayout(scales=(1.0,), marker_px=8.0)
    assert simulate_tracks(scene, layout=tiny, eval_points=0, eval_points_per_camera=0).tracks.counts_per_camera()[
        "far1"
    ] == 0


def test_noise_statistics_match_sigma():
    sigma = 0.7
    noisy = simulate_tracks("paper", noise_px=sigma, seed=5)
    residuals = reprojection_residuals(noisy, noisy.tracks, noisy.msm_points)
    # ~60k residual coordinates: one standard error of the sample std is ~0.3 % of sigma.
    assert residuals.std() == pytest.approx(sigma, rel=0.03)
    assert abs(residuals.mean()) < 0.02
    eval_residuals = reprojection_residuals(noisy, noisy.eval_tracks, noisy.eval_points)
    assert eval_residuals.std() == pytest.approx(sigma, rel=0.05)


def test_outlier_fraction():
    fraction = 0.1
    simulation = simulate_tracks("medium", noise_px=0.5, seed=2, outlier_fraction=fraction)
    tracks = simulation.tracks
    outliers = np.zeros(len(tracks), dtype=bool)
    ids = tracks.observation_ids()
    for index, name in enumerate(tracks.camera_names):
        outliers |= (tracks.camera_index == index) & np.isin(ids, simulation.outliers[name])
    assert outliers.sum() == round(fraction * len(tracks))
    errors = np.linalg.norm(reprojection_residuals(simulation, tracks, simulation.msm_points), axis=1)
    assert errors[~outliers].max() < 5.0  # 0.5 px noise: 10 sigma
    assert np.median(errors[outliers]) > 100.0


def test_seed_reproduces_and_changes_the_draws():
    first = simulate_tracks("small", seed=11)
    again = simulate_tracks("small", seed=11)
    other = simulate_tracks("small", seed=12)
    np.testing.assert_array_equal(first.tracks.xy, again.tracks.xy)
    np.testing.assert_array_equal(first.eval_points, again.eval_points)
    assert first.tracks.xy.shape != other.tracks.xy.shape or np.any(first.tracks.xy != other.tracks.xy)


def test_evaluation_points_fill_the_working_volume_and_every_view(or_full_clean):
    points, tracks = or_full_clean.eval_points, or_full_clean.eval_tracks
    assert points[:, 2].min() >= 0.0 and points[:, 2].max() <= 2.0
    assert tracks.track_lengths().min() >= 2
    # Points drawn inside each view give the zoomed camera ~100 evaluation points.
    assert tracks.counts_per_camera()["ceiling"] >= 50


def test_points_behind_a_camera_are_not_seen():
    camera = load_scene("small").cameras[0]
    behind = 2.0 * camera.center - np.array(camera.look_at)
    projection = project_points(camera, np.array([behind, camera.look_at]))
    assert projection.visible.tolist() == [False, True]
    assert np.isnan(projection.undistorted[0]).all()


def test_cli_simulate_tracks_only(tmp_path, capsys):
    out = tmp_path / "sim"
    status = main(["simulate", "--scene", "small", "--tracks-only", "--noise", "0.3", "--seed", "4",
                   "--out", str(out)])
    assert status == 0
    assert "cam1" in capsys.readouterr().out
    tracks = Tracks.read(out / "tracks.json")
    assert tracks.camera_names == ("cam1", "cam2", "cam3") and tracks.markers_per_array == 32
    assert Tracks.read(out / "eval_tracks.json").markers_per_array is None
    assert sorted(load_intrinsics_dir(out / "intrinsics")) == ["cam1", "cam2", "cam3"]
    assert read_scene(out / "scene.json") == load_scene("small")
    truth = json.loads((out / "truth.json").read_text())
    assert truth["simulation"]["noise_px"] == 0.3 and truth["simulation"]["seed"] == 4
    assert set(truth["cameras"]["cam1"]) >= {"R", "t", "center", "K", "dist", "resolution", "fps", "start_offset_s"}


def test_cli_rejects_bad_input(tmp_path, capsys):
    assert main(["simulate", "--scene", "nowhere", "--tracks-only", "--out", str(tmp_path)]) == 2
    assert "not a preset" in capsys.readouterr().err
    assert main(["simulate", "--scene", "small", "--tracks-only", "--outliers", "2", "--out", str(tmp_path)]) == 2
    assert "outlier fraction must be in [0, 1]" in capsys.readouterr().err
