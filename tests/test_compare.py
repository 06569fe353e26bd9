"""Pose comparison: Sim(3) invariance, known perturbations, missing cameras, pose files, CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calibproj.cli.main import main
from calibproj.evaluation.comparison import compare
from calibproj.formats.calibration import Calibration
from calibproj.formats.poses import CameraPoses, read_poses
from calibproj.simulate.geometric import simulate_tracks
from calibproj.simulate.scene import load_scene
from calibproj.simulate.truth import truth_document, write_truth


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' formula."""
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    cross = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    return rotation(rng.normal(size=3), rng.uniform(0.1, 3.0))


@pytest.fixture(scope="module")
def truth() -> CameraPoses:
    scene = load_scene("paper", seed=1)
    return CameraPoses({c.name: (c.R, c.t) for c in scene.cameras}, unit="m", source="truth")


def transformed(poses: dict, scale: float, Q: np.ndarray, u: np.ndarray) -> dict:
    """The same rig in the frame X' = scale Q X + u."""
    out = {}
    for name, (R, t) in poses.items():
        R_new = R @ Q.T
        out[name] = (R_new, scale * t - R_new @ u)
    return out


def test_truth_against_itself_under_a_random_similarity_has_no_error(truth):
    rng = np.random.default_rng(3)
    estimate = CameraPoses(transformed(truth.poses, 0.37, random_rotation(rng), rng.normal(size=3) * 5), "arbitrary")
    result = compare(estimate, truth)
    assert result.rotation_rmse_deg < 1e-9 and result.translation_rmse_pct < 1e-9
    assert result.translation_rmse_mm is None  # the estimate is not metric
    assert result.scale == pytest.approx(1 / 0.37)
    assert result.registered == truth.names and result.missing == []


def test_known_perturbation_gives_the_known_error(truth):
    rng = np.random.default_rng(4)
    names = truth.names
    centres = truth.centers(names)
    # Centre shifts with zero sum and zero cross-covariance with the centres: the Umeyama
    # alignment of the shifted rig then has no rotation and no translation about the
    # centroid, and its scale is var(c) / (var(c) + mean |shift|^2); so the centre
    # errors are known in closed form.
    offsets = centres - centres.mean(axis=0)
    constraints = np.vstack([np.kron(np.ones(len(names)), np.eye(3))] +
                            [np.kron(offsets[:, k], np.eye(3)) for k in range(3)])
    shifts = rng.normal(size=3 * len(names))
    shifts -= np.linalg.pinv(constraints) @ (constraints @ shifts)
    shifts = 0.01 * shifts.reshape(-1, 3)  # about a centimetre
    angles_deg = rng.uniform(0.05, 0.5, len(names))
    perturbed = {}
    for i, name in enumerate(names):
        R, _ = truth.poses[name]
        R_new = rotation(rng.normal(size=3), np.radians(angles_deg[i])) @ R
        perturbed[name] = (R_new, -R_new @ (centres[i] + shifts[i]))
    metric = compare(CameraPoses(perturbed, "m"), truth)
    variance = np.mean(np.sum(offsets**2, axis=1))
    scale = variance / (variance + np.mean(np.sum(shifts**2, axis=1)))
    expected_mm = 1000 * np.linalg.norm(scale * (offsets + shifts) - offsets, axis=1)
    assert metric.scale == pytest.approx(scale, rel=1e-12)
    for i, name in enumerate(names):
        assert metric.cameras[name].rotation_deg == pytest.approx(angles_deg[i], rel=1e-6)
        assert metric.cameras[name].translation_mm == pytest.approx(expected_mm[i], rel=1e-6)
    assert metric.rotation_rmse_deg == pytest.approx(np.sqrt(np.mean(angles_deg**2)), rel=1e-6)
    assert metric.translation_rmse_mm == pytest.approx(np.sqrt(np.mean(expected_mm**2)), rel=1e-6)
    # The same in another frame and unit: degrees and percentages do not change.
    Q = random_rotation(rng)
    arbitrary = compare(CameraPoses(transformed(perturbed, 2.5, Q, np.ones(3)), "arbitrary"), truth)
    assert arbitrary.translation_rmse_mm is None
    assert arbitrary.rotation_rmse_deg == pytest.approx(metric.rotation_rmse_deg, rel=1e-6)
    assert arbitrary.translation_rmse_pct == pytest.approx(metric.translation_rmse_pct, rel=1e-6)
    distances = np.linalg.norm(centres[:, None] - centres[None], axis=-1)[np.triu_indices(len(names), 1)]
    assert metric.cameras[names[0]].translation_pct == pytest.approx(expected_mm[0] / 10 / distances.mean(), rel=1e-6)


def test_missing_and_failed_cameras_are_reported(truth):
    poses = {name: pose for name, pose in truth.poses.items() if name not in ("near2", "far3")}
    failed = {"far5": "too few correspondences"}
    poses["stranger"] = truth.poses["far1"]
    result = compare(CameraPoses(poses, "m", failed), truth)
    assert result.missing == ["far3", "far5", "near2"]
    assert result.registered == [n for n in truth.names if n not in ("far3", "far5", "near2")]
    assert set(result.cameras) == set(result.registered)
    assert result.rotation_rmse_deg < 1e-9


def test_too_few_common_cameras_is_an_error(truth):
    two = {name: truth.poses[name] for name in ("far1", "far2")}
    with pytest.raises(ValueError, match="only 2 camera.*at least 3"):
        compare(CameraPoses(two, "m"), truth)


def test_centres_that_cannot_be_aligned_name_the_estimate(truth):
    """One camera 1e30 away: the others' centres coincide next to it, no similarity fits."""
    far = {**truth.poses, "far1": (truth.poses["far1"][0], np.array([-1e30, 0.0, 0.0]))}
    with pytest.raises(ValueError, match=r"^estimate.json: cannot be aligned on truth \(cameras far1, .*\): "):
        compare(CameraPoses(far, "m", source="estimate.json"), truth)


def write_camera_poses(path, poses, unit, failed=None) -> None:
    """camera_poses.json of these poses alone, as a calibration writes it."""
    assert path.name == "camera_poses.json"
    calibration = Calibration(poses, dict(failed or {}), {}, np.zeros((0, 3)), np.zeros(0, dtype=np.int64), unit=unit)
    calibration.save(path.parent)


def test_pose_files_refuse_booleans_and_strings_as_numbers(tmp_path, truth):
    path = tmp_path / "camera_poses.json"
    write_camera_poses(path, truth.poses, "m")
    for key, value, message in [("t", [True, 0, 0], "t: expected numbers, got true"),
                                ("R", [["1", 0, 0], [0, 1, 0], [0, 0, 1]], 'R: expected numbers, got "1"'),
                                ("weak", 1, "weak: expected true or false, got 1")]:
        document = json.loads(path.read_text())
        document["cameras"]["far1"][key] = value
        (tmp_path / "bad.json").write_text(json.dumps(document))
        with pytest.raises(ValueError, match=rf"bad\.json: cameras\.far1\.{message}"):
            read_poses(tmp_path / "bad.json")


def test_pose_files_round_trip_and_validation(tmp_path, truth):
    path = tmp_path / "camera_poses.json"
    write_camera_poses(path, truth.poses, "arbitrary", {"far9": "not seen"})
    read = read_poses(path)
    assert read.unit == "arbitrary" and read.failed == {"far9": "not seen"} and read.names == truth.names
    for name in truth.names:
        np.testing.assert_allclose(read.center(name), truth.center(name), atol=1e-12)
    document = json.loads(path.read_text())
    document["cameras"]["far1"]["R"][0][0] += 0.01
    path.write_text(json.dumps(document))
    with pytest.raises(ValueError, match=r"camera_poses\.json: cameras\.far1: R is not a rotation matrix"):
        read_poses(path)
    document["unit"] = "feet"
    path.write_text(json.dumps(document))
    with pytest.raises(ValueError, match="unit must be one of"):
        read_poses(path)
    path.write_text(json.dumps({"schema": "calibproj.tracks/1"}))
    with pytest.raises(ValueError, match="is a calibproj tracks file, expected camera_poses"):
        read_poses(path)
    with pytest.raises(ValueError, match="no such file"):
        read_poses(tmp_path / "absent.json")


def test_cli_compare_json_and_table(tmp_path, capsys):
    simulation = simulate_tracks("or-full", out=tmp_path / "sim", eval_points=0, eval_points_per_camera=0)
    scene = simulation.scene
    rng = np.random.default_rng(0)
    poses = {}
    for camera in scene.cameras[:-1]:
        R = rotation(rng.normal(size=3), np.radians(0.1)) @ camera.R  # turned 0.1 deg about its centre
        poses[camera.name] = (R, -R @ camera.center)
    estimate = tmp_path / "camera_poses.json"
    write_camera_poses(estimate, poses, "m", {"ceiling": "no overlap"})
    assert main(["compare", str(estimate), str(tmp_path / "sim" / "truth.json"), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert set(result) == {"rotation_rmse_deg", "translation_rmse_mm", "translation_rmse_pct", "registered",
                           "missing", "cameras"}
    assert result["missing"] == ["ceiling"] and len(result["registered"]) == 8
    assert set(result["cameras"]["far1"]) == {"rotation_deg", "translation_mm", "translation_pct"}
    assert result["rotation_rmse_deg"] == pytest.approx(0.1, rel=1e-6)
    assert result["translation_rmse_mm"] < 1e-6
    assert main(["compare", str(estimate), str(tmp_path / "sim" / "truth.json")]) == 0
    table = capsys.readouterr().out
    assert "far1" in table and "RMSE" in table and "missing: ceiling" in table
    assert main(["compare", str(tmp_path / "absent.json"), str(tmp_path / "sim" / "truth.json")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_truth_file_is_read_like_camera_poses(tmp_path):
    scene = load_scene("small")
    write_truth(tmp_path / "truth.json", truth_document(scene, (np.arange(2), np.zeros((2, 3))), 32))
    poses = read_poses(tmp_path / "truth.json")
    assert poses.unit == "m" and poses.names == ["cam1", "cam2", "cam3"]
    np.testing.assert_allclose(poses.poses["cam2"][0], scene.cameras[1].R)


def test_rotation_errors_relative_to_the_reference_ignore_a_common_rotation() -> None:
    """A frame turned as a whole changes no relative rotation; a camera turned by a known
    tiny angle shows exactly that angle, the reference none."""
    from calibproj.evaluation.comparison import rotation_errors_to_reference
    from calibproj.simulate.synthetic import matrix_from_rotvec

    rng = np.random.default_rng(3)
    truth = {name: matrix_from_rotvec(rng.normal(size=3)) for name in ("a", "b", "c")}
    frame = matrix_from_rotvec(np.array([0.3, -0.2, 0.9]))
    poses = {name: (R @ frame, np.zeros(3)) for name, R in truth.items()}
    turn = np.radians(0.001)
    poses["c"] = (matrix_from_rotvec(np.array([0.0, turn, 0.0])) @ poses["c"][0], np.zeros(3))
    errors = rotation_errors_to_reference(poses, "a", truth)
    assert set(errors) == {"b", "c"}
    assert errors["b"] == pytest.approx(0.0, abs=1e-9)
    assert errors["c"] == pytest.approx(0.001, rel=1e-6)
