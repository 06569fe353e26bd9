"""The expected triangulation error from the poses' joint covariance, against the spread
of re-noised solutions; uncertainty.json as calibrate writes it; the API's errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from calibproj import _core, triangulation_uncertainty
from calibproj.formats.calibration import Calibration, CameraMetrics
from calibproj.formats.intrinsics import Intrinsics
from calibproj.formats.jsonio import FormatError
from calibproj.pipeline import calibrate
from calibproj.simulate import simulate_tracks
from calibproj.simulate.synthetic import matrix_from_rotvec, paper_ring_rig

SIGMA_PX = 0.5


def _calibration_of(rig, poses: np.ndarray, covariance: np.ndarray) -> tuple[Calibration, dict[str, Intrinsics]]:
    names = [f"cam{c}" for c in range(len(poses))]
    posed = {name: (matrix_from_rotvec(pose[:3]), pose[3:].copy()) for name, pose in zip(names, poses)}
    metrics = {name: CameraMetrics(0.5, 0.1, 1, 1, 1, 1) for name in names}
    uncertainty = _core.uncertainty.PoseUncertainty(names, names[0], covariance, [SIGMA_PX] * len(names))
    calibration = Calibration(posed, {}, metrics, rig.points, np.arange(len(rig.points)), unit="m",
                              registration_order=names, uncertainty=uncertainty)
    intrinsics = {name: Intrinsics(name, rig.resolution, rig.K[c], np.zeros(5)) for c, name in enumerate(names)}
    return calibration, intrinsics


def _project(K: np.ndarray, pose: np.ndarray, X: np.ndarray) -> np.ndarray:
    x = matrix_from_rotvec(pose[:3]) @ X + pose[3:]
    return (K @ (x / x[2]))[:2]


def _triangulate(Ks, poses, pixels, weights, start: np.ndarray) -> np.ndarray:
    """Weighted Gauss-Newton from `start`, numeric Jacobians: an independent triangulation."""
    X = start.copy()
    for _ in range(5):
        H, g = np.zeros((3, 3)), np.zeros(3)
        for K, pose, u, W in zip(Ks, poses, pixels, weights):
            r = _project(K, pose, X) - u
            J = np.column_stack([(_project(K, pose, X + e) - _project(K, pose, X - e)) / 2e-6
                                 for e in np.eye(3) * 1e-6])
            H += J.T @ W @ J
            g += J.T @ W @ r
        X = X - np.linalg.solve(H, g)
    return X


def test_predicted_triangulation_error_matches_re_noised_calibrations() -> None:
    """A rig calibrated 200 times from fresh 0.5 px noise (the reference camera's pose and
    the floor's distance held, as in calibproj); each time points of the room are
    triangulated from fresh pixels with the calibration of that run. The spread of the
    points matches the prediction within 25 %, and the prediction's cross terms matter."""
    rig = paper_ring_rig(seed=5, noise_px=0.0, num_points=150)
    nominal = _core.ba.bundle_adjust(rig.camera_index, rig.point_index, rig.observed, rig.K, rig.poses, rig.points,
                                     rig.plane, model="coplanar", compute_covariance=True)
    calibration, intrinsics = _calibration_of(rig, rig.poses, SIGMA_PX**2 * nominal.pose_covariance)
    targets = np.array([[0.3, -0.2, 0.9], [-0.6, 0.4, 1.7], [0.9, 0.5, 0.0]])
    predicted = triangulation_uncertainty(calibration, targets, intrinsics=intrinsics)
    assert np.isfinite(predicted.sigma).all()
    names = list(calibration.poses)
    rng = np.random.default_rng(3)
    runs = []
    for _ in range(200):
        noisy = rig.observed + rng.normal(0.0, SIGMA_PX, rig.observed.shape)
        solved = _core.ba.bundle_adjust(rig.camera_index, rig.point_index, noisy, rig.K, rig.poses, rig.points,
                                        rig.plane, model="coplanar").poses
        placed = []
        for X, seen in zip(targets, predicted.cameras):
            cams = [names.index(name) for name in seen]
            pixels = [_project(rig.K[c], rig.poses[c], X) + rng.normal(0.0, SIGMA_PX, 2) for c in cams]
            # The prediction's weights: each camera's pixel noise and its own pose's spread.
            weights = [np.linalg.inv(SIGMA_PX**2 * np.eye(2) + _core.uncertainty.projection(
                calibration, intrinsics, names[c], X[None])[0]) for c in cams]
            placed.append(_triangulate(rig.K[cams], solved[cams], pixels, weights, X))
        runs.append(placed)
    runs = np.array(runs)  # (runs, targets, 3)
    for k in range(len(targets)):
        empirical = np.cov(runs[:, k].T)
        ratio = np.sqrt(np.trace(empirical) / np.trace(predicted.covariance[k]))
        assert 0.75 < ratio < 1.25, (k, ratio)
        assert np.linalg.norm(runs[:, k].mean(axis=0) - targets[k]) < 0.3 * predicted.sigma[k]
    # The poses' share, and within it the cross terms between cameras, are not negligible.
    blocks_only = calibration.replace(uncertainty=_core.uncertainty.PoseUncertainty(
        names, names[0], _block_diagonal(calibration.uncertainty.covariance), [SIGMA_PX] * len(names)))
    without_cross = triangulation_uncertainty(blocks_only, targets, intrinsics=intrinsics)
    assert np.max(np.abs(without_cross.sigma / predicted.sigma - 1.0)) > 0.1


def _block_diagonal(covariance: np.ndarray) -> np.ndarray:
    out = np.zeros_like(covariance)
    for c in range(0, len(covariance), 6):
        out[c:c + 6, c:c + 6] = covariance[c:c + 6, c:c + 6]
    return out


@pytest.fixture(scope="module")
def demo_results(tmp_path_factory) -> Path:
    sim = simulate_tracks("demo", None, noise_px=0.2, seed=0)
    out = tmp_path_factory.mktemp("uncertainty") / "results"
    calibrate(sim.tracks, sim.intrinsics, out=out, scale="camera-height:far1=2.7", report=False, progress=False)
    return out


def test_calibrate_writes_the_expected_error_over_the_working_volume(demo_results: Path) -> None:
    document = json.loads((demo_results / "uncertainty.json").read_text())
    assert document["schema"] == "calibproj.uncertainty/1" and document["unit"] == "m"
    reference = document["gauge"]["reference_camera"]
    cameras = {camera["name"]: camera for camera in document["cameras"]}
    assert cameras[reference]["projection_sigma_px"] == {"median": 0.0, "max": 0.0}
    # The noise each camera's centres show: the simulation's 0.2 px.
    assert all(0.15 < camera["noise_px"] < 0.25 for camera in cameras.values())
    grid = document["map"]
    assert grid["z"] == [0.0, 0.5, 0.9, 1.3, 1.7, 2.0]
    sigma = np.array(grid["sigma"], dtype=float)
    assert sigma.shape == (6, len(grid["y"]), len(grid["x"]))
    seen = [[[len(cell) for cell in row] for row in level] for level in grid["seen_by"]]
    assert np.array_equal(np.isfinite(sigma), np.array(seen) >= 2)
    # Millimetres over the room with 0.2 px centres: well below a centimetre.
    assert 0.0002 < document["volume"]["median_sigma"] < 0.005
    assert document["volume"]["cells_seen_by_2"] == int(np.isfinite(sigma).sum())
    # The API reads the folder and gives the file's figure at the projection's centre.
    centre = document["centre"]
    answer = triangulation_uncertainty(demo_results, centre["point"])
    assert answer.sigma[0] == pytest.approx(centre["sigma"], rel=1e-5)
    assert answer.cameras[0] == centre["cameras"] and answer.unit == "m"
    # A point no two cameras see has no figure.
    assert np.isnan(triangulation_uncertainty(demo_results, [[50.0, 50.0, 1.0]]).sigma).all()


def test_a_results_folder_without_or_with_a_damaged_uncertainty_file_says_so(demo_results: Path,
                                                                            tmp_path: Path) -> None:
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(demo_results, copy)
    (copy / "uncertainty.json").unlink()
    with pytest.raises(FormatError, match=r"uncertainty\.json: no such file"):
        triangulation_uncertainty(copy, [0.0, 0.0, 0.9])
    document = json.loads((demo_results / "uncertainty.json").read_text())
    for damage in ({"pose_covariance": None}, {"gauge": {"reference_camera": "nobody"}}):
        (copy / "uncertainty.json").write_text(json.dumps({**document, **damage}))
        with pytest.raises(FormatError) as error:
            triangulation_uncertainty(copy, [0.0, 0.0, 0.9])
        assert "uncertainty.json" in str(error.value) and "\n" not in str(error.value)
    with pytest.raises(ValueError, match="noise_px"):
        triangulation_uncertainty(demo_results, [0.0, 0.0, 0.9], noise_px=-1.0)


def test_the_report_leads_with_the_expected_error_and_maps_it(demo_results: Path, tmp_path: Path) -> None:
    import shutil

    from calibproj.report import write_report

    folder = tmp_path / "results"
    shutil.copytree(demo_results, folder)
    page = write_report(folder).read_text()
    document = json.loads((folder / "uncertainty.json").read_text())
    headline = page[page.index('<div class="headline">'):page.index("</div>", page.index('<div class="headline">'))]
    assert f"Expected 3D error {1000 * document['centre']['sigma']:.1f} mm</b>" in headline
    assert f"{1000 * document['volume']['median_sigma']:.1f} mm at the median" in headline
    for level in ("floor", "table", "head"):
        assert (folder / "report" / f"uncertainty_{level}.png").stat().st_size > 10_000
    caption = "<figcaption>Expected 3D error at the table, 0.9 m</figcaption>"
    assert caption in page
    for camera in document["cameras"]:
        assert f"<td>{camera['name']}</td><td>{camera['noise_px']:.3f}</td>" in page
    # Without the file the report says nothing of it, and a damaged one draws no map.
    (folder / "uncertainty.json").write_text(json.dumps({**document, "map": {"x": "damaged"}}))
    page = write_report(folder).read_text()
    assert "Expected 3D error" in page and caption not in page
    (folder / "uncertainty.json").unlink()
    assert "Expected 3D error" not in write_report(folder).read_text()


def test_damaged_uncertainty_files_give_one_clear_line(demo_results: Path, tmp_path: Path) -> None:
    """uncertainty.json mutated every way the fuzz tests mutate the other files (entries
    replaced by wrong types, huge, NaN or deeply nested values, deleted; truncations,
    byte flips): the API answers, or raises FormatError (ValueError) naming the file in
    one line; nothing else escapes and nothing crashes."""
    import shutil

    from fuzz_inputs import byte_level, structural

    folder = tmp_path / "results"
    shutil.copytree(demo_results, folder)
    valid = (demo_results / "uncertainty.json").read_bytes()
    document = json.loads(valid)
    # The matrix and the map are long: mutate a document with their first rows only,
    # besides the full one's bytes.
    small = {**document, "map": {key: value[:2] if isinstance(value, list) else value
                                 for key, value in document["map"].items()}}
    rng = np.random.default_rng(7)
    mutations = structural(small, rng, 60) + structural(document, rng, 20) + byte_level(valid, rng, 20)
    calibration = Calibration.load(folder)
    for mutation in mutations:
        (folder / "uncertainty.json").write_bytes(mutation.data)
        # What check reads to carry the covariance into a repair: the covariance, or why not.
        stored, warning = _core.uncertainty.stored_pose_uncertainty(folder, calibration)
        assert (stored is None) == bool(warning), mutation.label
        assert "\n" not in warning and (not warning or "uncertainty.json" in warning), (mutation.label, warning)
        try:
            answer = triangulation_uncertainty(folder, [[0.0, 0.0, 0.9]])
        except ValueError as error:  # FormatError among them
            message = str(error)
            assert "\n" not in message and len(message) < 2000, mutation.label
            assert "uncertainty.json" in message or "pose covariance" in message, (mutation.label, message)
            continue
        assert not mutation.must_fail, mutation.label
        assert answer.covariance.shape == (1, 3, 3)


def test_the_free_model_says_which_distance_it_held(tmp_path: Path) -> None:
    from calibproj.registration.driver import RegistrationOptions

    sim = simulate_tracks("small", None, noise_px=0.3, seed=2)
    calibrate(sim.tracks, sim.intrinsics, out=tmp_path / "r", options=RegistrationOptions(model="free"),
              report=False, progress=False)
    document = json.loads((tmp_path / "r" / "uncertainty.json").read_text())
    assert "distance to the camera farthest from it" in document["gauge"]["held"]
    assert document["volume"]["cells_seen_by_2"] > 0


def _lens_intrinsics(lens: np.ndarray, aspect: float, skew_ratio: float) -> Intrinsics:
    """Intrinsics of a lens block [f, cx, cy, k1, k2, p1, p2, k3] and its shape."""
    f, cx, cy, k1, k2, p1, p2, k3 = lens
    K = np.array([[f, skew_ratio * f, cx], [0.0, aspect * f, cy], [0.0, 0.0, 1.0]])
    return Intrinsics("lens", (1280, 960), K, np.array([k1, k2, p1, p2, k3]))


def test_a_lens_error_moves_the_residual_as_its_derivative_says() -> None:
    """d residual / d lens of a centre (the undistorted pixel residual that the bundle
    adjustment sees, for a raw pixel undistorted with the lens) against central
    differences of undistorting the same raw pixel with a perturbed lens."""
    lens = np.array([610.0, 655.0, 470.0, -0.26, 0.09, 3e-4, -2e-4, -0.012])
    aspect, skew_ratio = 1.002, 0.0  # Intrinsics files carry no skew
    truth = _lens_intrinsics(lens, aspect, skew_ratio)
    for normalised in ([0.1, -0.2], [-0.55, 0.38], [0.0, 0.0]):
        projected = truth.K[:2, :2] @ np.array(normalised) + truth.K[:2, 2]  # the model's undistorted pixel
        raw = truth.distort_points(projected[None])
        analytic = _core.selfcal.residual_by_lens(truth.K, truth.dist, np.array(normalised))
        numeric = np.zeros((2, 8))
        for entry in range(8):
            step = 1e-4 * max(1.0, abs(lens[entry])) if entry < 3 else 1e-6
            sides = []
            for sign in (1.0, -1.0):
                moved = lens.copy()
                moved[entry] += sign * step
                other = _lens_intrinsics(moved, aspect, skew_ratio)
                n = other.normalize(other.undistort_points(raw))[0]
                # Projected minus observed, both in the moved lens's pinhole pixels.
                sides.append(other.K[:2, :2] @ (np.array(normalised) - n))
            numeric[:, entry] = (sides[0] - sides[1]) / (2 * step)
        assert np.allclose(analytic, numeric, rtol=1e-4, atol=1e-6 * np.abs(analytic).max()), (normalised, analytic, numeric)


def _pose_change(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """[dtheta, dt] per camera with R_after = Exp(dtheta) R_before (6C,)."""
    from scipy.spatial.transform import Rotation

    out = []
    for a, b in zip(before, after):
        dtheta = (Rotation.from_rotvec(b[:3]) * Rotation.from_rotvec(a[:3]).inv()).as_rotvec()
        out.append(np.concatenate([dtheta, b[3:] - a[3:]]))
    return np.concatenate(out)


@pytest.mark.parametrize("model", ["coplanar", "free"])
def test_the_poses_sensitivity_to_a_lens_matches_solving_again(model: str) -> None:
    """A lens the bundle adjustment holds moves the observations it was undistorted with;
    the sensitivity the adjustment reports (from its reduced system) matches the poses'
    change when it is solved again with the observations moved, entry by entry."""
    rig = paper_ring_rig(seed=2, noise_px=0.0, num_points=120)
    rng = np.random.default_rng(4)
    lens_block = np.full(len(rig.K), -1)
    lens_block[[1, 3]] = [0, 1]
    jacobians = rng.normal(0.0, 1.0, (len(rig.camera_index), 16)) * 0.01
    jacobians[:, [0, 8]] = rng.normal(0.0, 0.5, (len(rig.camera_index), 2))  # focal: up to a pixel
    jacobians[lens_block[rig.camera_index] < 0] = 0.0
    solve = dict(model=model, compute_covariance=True, lens_block=lens_block, lens_jacobians=jacobians,
                 loss="huber", loss_scale=0.5)
    solved = _core.ba.bundle_adjust(rig.camera_index, rig.point_index, rig.observed, rig.K, rig.poses, rig.points,
                                    rig.plane, **solve)
    sensitivity = solved.lens_sensitivity
    assert sensitivity.shape == (6 * len(rig.K), 16)
    assert np.allclose(sensitivity[:6], 0.0)  # the gauge camera's pose is held
    for column in (0, 3, 8, 12):
        step = 1e-3
        moved = []
        for sign in (1.0, -1.0):
            J = jacobians.reshape(-1, 2, 8)[:, :, column % 8] * (lens_block[rig.camera_index] == column // 8)[:, None]
            # r = projected - observed: a lens change dr = J dk is the observations moving by -J dk.
            observed = rig.observed - sign * step * J
            moved.append(_core.ba.bundle_adjust(rig.camera_index, rig.point_index, observed, rig.K, solved.poses,
                                                solved.points, solved.plane, model=model, loss="huber",
                                                loss_scale=0.5).poses)
        numeric = _pose_change(moved[1], moved[0]) / (2 * step)
        assert np.abs(numeric).max() > 1e-6
        assert np.allclose(sensitivity[:, column], numeric, rtol=2e-3, atol=2e-3 * np.abs(numeric).max()), column


@pytest.fixture(scope="module")
def refined_results(tmp_path_factory) -> tuple[Path, Path]:
    """The demo room calibrated from intrinsics 5 % off, refining them, and with the true
    intrinsics taken as exact."""
    from calibproj.selfcal.lenses import convert_tracks

    sim = simulate_tracks("demo", None, noise_px=0.2, seed=0)
    given = {}
    for name, truth in sim.intrinsics.items():
        K = truth.K.copy()
        K[:2, :2] *= 1.05
        given[name] = Intrinsics(name, truth.resolution, K, truth.dist.copy())
    folder = tmp_path_factory.mktemp("refined")
    calibrate(convert_tracks(sim.tracks, sim.intrinsics, given), given, out=folder / "refined", report=False,
              progress=False, refine_intrinsics="focal,k1")
    calibrate(sim.tracks, sim.intrinsics, out=folder / "exact", report=False, progress=False)
    return folder / "refined", folder / "exact"


def test_refined_lenses_and_their_cross_terms_enter_the_expected_error(refined_results) -> None:
    refined, exact = refined_results
    document = json.loads((refined / "uncertainty.json").read_text())
    refined_cameras = [name for name, report in json.loads((refined / "self_calibration.json").read_text())
                       ["cameras"].items() if "focal" in report["refined"]]
    assert refined_cameras
    covariance = document["pose_covariance"]
    blocks = dict(zip(covariance["cameras"], covariance["lens_block"]))
    assert sorted(name for name, block in blocks.items() if block is not None) == sorted(refined_cameras)
    assert covariance["lens_entries"] == ["f", "cx", "cy", "k1", "k2", "p1", "p2", "k3"]
    assert "refined lenses" in document["intrinsics"]
    matrix = np.array(covariance["matrix"])
    C = len(covariance["cameras"])
    assert matrix.shape == (6 * C + 8 * len(refined_cameras),) * 2
    # The focal lengths' variance is the self-calibration's; a pose and its own lens err together.
    camera = next(name for name in refined_cameras if name != document["gauge"]["reference_camera"])
    index, block = covariance["cameras"].index(camera), blocks[camera]
    focal = 6 * C + 8 * block
    assert 0.0 < matrix[focal, focal] < (0.01 * 640) ** 2
    assert np.abs(matrix[6 * index:6 * index + 6, focal]).max() > 0.0
    # Lenses fitted to the same floor points err together, and the whole stays a covariance.
    other = next(name for name in refined_cameras if name != camera)
    other_focal = 6 * C + 8 * blocks[other]
    assert matrix[focal, other_focal] != 0.0
    assert matrix[focal, other_focal] == pytest.approx(matrix[other_focal, focal], rel=1e-12)
    assert np.linalg.eigvalsh(matrix).min() >= -1e-9 * np.abs(matrix).max()
    # A pose known less well with its lens refined than with the lens taken as exact.
    exact_matrix = np.array(json.loads((exact / "uncertainty.json").read_text())["pose_covariance"]["matrix"])
    worse = [np.trace(matrix[6 * k + 3:6 * k + 6, 6 * k + 3:6 * k + 6]) >
             np.trace(exact_matrix[6 * k + 3:6 * k + 6, 6 * k + 3:6 * k + 6])
             for k, name in enumerate(covariance["cameras"])
             if name in refined_cameras and name != document["gauge"]["reference_camera"]]
    assert worse and all(worse)
    # The file reads back (lens blocks included) and the API answers as the file does.
    centre = document["centre"]
    answer = triangulation_uncertainty(refined, centre["point"])
    assert answer.sigma[0] == pytest.approx(centre["sigma"], rel=1e-5)


def test_lens_cross_covariances_must_agree_with_the_lenses() -> None:
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    reconstruction = _core.registration.Reconstruction(np.stack([K, K, K]), np.array([[640, 480]] * 3), 1,
                                                       np.array([0, 1, 2]), np.array([0, 0, 0]),
                                                       np.array([[1.0, 2], [3, 4], [5, 6]]))
    first, third = np.diag([0.25, 0, 0, 1e-6, 0, 0, 0, 0]), np.diag([0.16, 0, 0, 4e-6, 0, 0, 0, 0])
    reconstruction.set_lens_uncertainty(0, K, [0.0] * 5, first)
    reconstruction.set_lens_uncertainty(2, K, [0.0] * 5, third)
    joint = np.zeros((16, 16))
    joint[:8, :8], joint[8:, 8:] = first, third
    joint[0, 8] = joint[8, 0] = 0.1  # focal lengths correlated by 0.5
    reconstruction.set_lens_cross_covariances([0, 2], joint)
    impossible = joint.copy()
    impossible[0, 8] = impossible[8, 0] = 0.3  # a correlation of 1.5
    for cameras, matrix, problem in [([0, 1], joint, "camera 1 has no lens"),
                                     ([0, 2], 2 * joint, "camera 0's block differs from its lens's covariance"),
                                     ([0, 0], joint, "camera 0 out of range or repeated"),
                                     ([0], joint, "expected a 8 x 8 matrix for 1 cameras"),
                                     ([0, 2], impossible, "not a finite symmetric positive semi-definite matrix")]:
        with pytest.raises(ValueError, match=problem):
            reconstruction.set_lens_cross_covariances(cameras, matrix)
