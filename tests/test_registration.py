"""Incremental registration against simulated rigs with known truth."""

from __future__ import annotations

import json
import logging
import re
from dataclasses import replace

import numpy as np
import pytest

from calibproj import _core
from calibproj.formats.calibration import Calibration
from calibproj.evaluation.comparison import compare, rotation_errors_to_reference
from calibproj.formats.poses import CameraPoses
from calibproj.registration.driver import RegistrationDriver, RegistrationOptions, register
from calibproj.simulate import simulate_tracks
from calibproj.simulate.scene import FloorRelief
from calibproj.simulate.synthetic import matrix_from_rotvec, rotvec_from_matrix
from calibproj.formats.tracks import Tracks

# Bounds of the registration issue (paper section 3.1 rig, 0.5 px noise).
MAX_ROTATION_RMSE_DEG = 0.02
MAX_TRANSLATION_RMSE_PCT = 0.05


def truth_poses(sim) -> CameraPoses:
    return CameraPoses({camera.name: (camera.R, camera.t) for camera in sim.scene.cameras}, "m")


def errors(calibration, sim):
    result = compare(CameraPoses(calibration.poses, calibration.unit, calibration.failed), truth_poses(sim))
    return result.rotation_rmse_deg, result.translation_rmse_pct, result


def cost_from_truth(driver: RegistrationDriver, sim, model: str) -> float:
    """Final cost of a bundle adjustment started from the true poses and points, with the
    observations the registration kept."""
    rec = driver.reconstruction
    camera_index, point_index, xy = driver.tracks.bundle_arrays()
    keep = rec.active & rec.registered[camera_index] & rec.reconstructed[point_index]
    cameras = np.flatnonzero(rec.registered)
    points = np.unique(point_index[keep])
    camera_map = np.full(rec.num_cameras, -1)
    camera_map[cameras] = np.arange(len(cameras))
    point_map = np.full(rec.num_points, -1)
    point_map[points] = np.arange(len(points))
    by_name = {c.name: c for c in sim.scene.cameras}
    names = [driver.tracks.camera_names[c] for c in cameras]
    poses = np.array([np.concatenate([rotvec_from_matrix(by_name[n].R), by_name[n].t]) for n in names])
    K = np.array([by_name[n].K for n in names])
    X = sim.msm_points[np.asarray(driver.tracks.point_ids)[points]]
    result = _core.ba.bundle_adjust(
        camera_map[camera_index[keep]], point_map[point_index[keep]], xy[keep], K, poses, X,
        np.array([0.0, 0.0, 1.0, 0.0]), model=model,
    )
    return result.final_cost


@pytest.mark.parametrize("model", ["coplanar", "free"])
@pytest.mark.parametrize("seed", range(20))
def test_paper_rig_reaches_the_global_optimum_within_bounds(model: str, seed: int) -> None:
    sim = simulate_tracks("paper", None, noise_px=0.5, seed=seed)
    # One noise for every camera: the cost from the truth is the unweighted one; an
    # exactly flat floor: the cost from the truth is that of the same model.
    options = RegistrationOptions(model=model, estimate_noise=False, floor_relief=0.0)
    driver = RegistrationDriver(sim.tracks, sim.intrinsics, options)
    calibration = driver.run()
    assert calibration.failed == {}
    assert sorted(calibration.registered) == sorted(sim.tracks.camera_names)
    rotation, translation, _ = errors(calibration, sim)
    assert rotation < MAX_ROTATION_RMSE_DEG
    assert translation < MAX_TRANSLATION_RMSE_PCT
    final = driver.reconstruction.adjust(True).final_cost
    assert abs(final - cost_from_truth(driver, sim, model)) / final < 1e-6
    # The floor frame: points on z = 0, cameras above it, first registered camera at height 1.
    if model == "coplanar":
        assert calibration.floor_rms < 1e-9
    else:  # triangulated points scatter about the fitted floor by their noise
        assert np.median(np.abs(calibration.points[:, 2])) < 2e-3
    first = calibration.registration_order[0]
    assert abs(calibration.center(first)[2] - 1.0) < 1e-9


@pytest.mark.parametrize("model", ["coplanar", "free"])
def test_gross_outliers_leave_the_result_within_bounds(model: str) -> None:
    sim = simulate_tracks("paper", None, noise_px=0.5, seed=3, outlier_fraction=0.05)
    calibration = register(sim.tracks, sim.intrinsics, RegistrationOptions(model=model))
    assert calibration.failed == {}
    rotation, translation, _ = errors(calibration, sim)
    assert rotation < MAX_ROTATION_RMSE_DEG
    assert translation < MAX_TRANSLATION_RMSE_PCT
    # Most planted outliers were removed: they are far outside the noise.
    kept = sum(m.inliers for m in calibration.metrics.values())
    total = sum(m.observations for m in calibration.metrics.values())
    assert 0.9 < kept / total < 0.96


def predicted_rotation_sigma_deg(sim, camera: str, gauge: str, model: str) -> float:
    """Largest rotation standard deviation of a camera (Cramer-Rao bound at 0.5 px): the
    pose covariance of a bundle adjustment of the true scene with the simulated observations."""
    camera_index, point_index, xy = sim.tracks.bundle_arrays()
    names = list(sim.tracks.camera_names)
    by_name = {c.name: c for c in sim.scene.cameras}
    poses = np.array([np.concatenate([rotvec_from_matrix(by_name[n].R), by_name[n].t]) for n in names])
    K = np.array([by_name[n].K for n in names])
    X = sim.msm_points[np.asarray(sim.tracks.point_ids)]
    result = _core.ba.bundle_adjust(
        camera_index, point_index, xy, K, poses, X, np.array([0.0, 0.0, 1.0, 0.0]), model=model,
        gauge_camera=names.index(gauge), compute_covariance=True,
    )
    covariance = result.pose_covariances[names.index(camera)][:3, :3]
    return float(np.degrees(np.sqrt(np.linalg.eigvalsh(covariance).max())))


@pytest.mark.parametrize("model", ["coplanar", "free"])
def test_or_full_registers_the_close_up_camera(model: str) -> None:
    """The zoomed camera (fx 11,100) sees 58 MSMs on 0.5 x 0.3 m of floor. At 0.5 px its
    rotation is only known to ~0.5 deg (the near-affine view trades rotation for lateral
    translation), so it is held to its Cramer-Rao bound; the other cameras to the paper bounds."""
    sim = simulate_tracks("or-full", None, noise_px=0.5, seed=0)
    calibration = register(sim.tracks, sim.intrinsics, RegistrationOptions(model=model))
    assert calibration.failed == {}
    _, _, result = errors(calibration, sim)
    close_up = "ceiling"
    assert calibration.metrics[close_up].mean_px < 1.0
    sigma = predicted_rotation_sigma_deg(sim, close_up, gauge="far1", model=model)
    assert result.cameras[close_up].rotation_deg < 3.0 * sigma
    # The others, aligned without the close-up camera (its centre is known to ~1 cm).
    others = {name: pose for name, pose in calibration.poses.items() if name != close_up}
    truth = truth_poses(sim)
    truth_others = CameraPoses({n: p for n, p in truth.poses.items() if n != close_up}, "m")
    result_others = compare(CameraPoses(others, calibration.unit), truth_others)
    assert result_others.rotation_rmse_deg < MAX_ROTATION_RMSE_DEG
    assert result_others.translation_rmse_pct < MAX_TRANSLATION_RMSE_PCT


def relabel_points(tracks: Tracks, cameras: list[str], offset: int) -> Tracks:
    """The same observations, but the given cameras see points nobody else sees."""
    ids = np.asarray(tracks.point_ids)[tracks.point_index].copy()
    moved = np.isin(np.asarray(tracks.camera_names)[tracks.camera_index], cameras)
    ids[moved] += offset
    return Tracks.from_observations(
        tracks.camera_names, tracks.camera_index, ids, tracks.xy, tracks.markers_per_array
    )


def test_a_lone_camera_is_told_it_needs_a_second() -> None:
    sim = simulate_tracks("small", None, noise_px=0.5, seed=5)
    names = np.asarray(sim.tracks.camera_names)[sim.tracks.camera_index]
    lone = sim.tracks.camera_names[0]
    calibration = register(sim.tracks.select(names == lone), sim.intrinsics)
    assert calibration.failed[lone].startswith("the only camera with observations (a calibration needs two")
    assert all(calibration.failed[name] == "no observations" for name in sim.tracks.camera_names[1:])


def test_disconnected_group_and_camera_with_too_few_points_are_reported() -> None:
    sim = simulate_tracks("paper", None, noise_px=0.5, seed=5)
    tracks = relabel_points(sim.tracks, ["far5", "far6"], offset=1_000_000)
    # near4 keeps only 4 of its observations.
    names = np.asarray(tracks.camera_names)[tracks.camera_index]
    keep = np.ones(len(tracks), bool)
    keep[np.flatnonzero(names == "near4")[4:]] = False
    tracks = tracks.select(keep)
    calibration = register(tracks, sim.intrinsics)
    assert set(calibration.failed) == {"far5", "far6", "near4"}
    assert "disconnected" in calibration.failed["far5"]
    assert "only 4 points" in calibration.failed["near4"]
    assert calibration.metrics["far5"].failure == calibration.failed["far5"]
    rotation, translation, _ = errors(calibration, sim)
    assert rotation < MAX_ROTATION_RMSE_DEG and translation < MAX_TRANSLATION_RMSE_PCT


def test_missing_intrinsics_fail_one_camera_only() -> None:
    sim = simulate_tracks("paper", None, noise_px=0.5, seed=6)
    intrinsics = dict(sim.intrinsics)
    del intrinsics["far2"]
    calibration = register(sim.tracks, intrinsics)
    assert calibration.failed == {"far2": "no intrinsics for this camera"}
    assert len(calibration.registered) == len(sim.tracks.camera_names) - 1


def test_homography_decomposition_recovers_the_true_motion() -> None:
    sim = simulate_tracks("paper", None, noise_px=0.0, seed=2)
    cam1, cam2 = sim.scene.cameras[0], sim.scene.cameras[6]
    ci, pi, xy = sim.tracks.bundle_arrays()
    c1, c2 = sim.tracks.camera_names.index(cam1.name), sim.tracks.camera_names.index(cam2.name)
    seen1 = dict(zip(pi[ci == c1], xy[ci == c1]))
    seen2 = dict(zip(pi[ci == c2], xy[ci == c2]))
    common = sorted(set(seen1) & set(seen2))
    assert len(common) > 100

    def normalised(camera, pixels):
        return (np.linalg.inv(camera.K) @ np.column_stack([pixels, np.ones(len(pixels))]).T).T[:, :2]

    x1 = normalised(cam1, np.array([seen1[p] for p in common]))
    x2 = normalised(cam2, np.array([seen2[p] for p in common]))
    ok, H, inliers = _core.geometry.estimate_homography(x1, x2, 1.0, cam1.K[0, 0], cam2.K[0, 0])
    assert ok and len(inliers) == len(common)
    motions = _core.geometry.decompose_homography(H, x1, x2)
    R_true = cam2.R @ cam1.R.T
    t_true = cam2.t - R_true @ cam1.t
    distance = cam1.center[2]  # camera 1 height above the floor z = 0
    n_true = cam1.R @ np.array([0.0, 0.0, -1.0])  # floor normal pointing away from camera 1
    best = min(
        motions,
        key=lambda m: np.linalg.norm(m[0] - R_true) + np.linalg.norm(m[1] * distance - t_true),
    )
    np.testing.assert_allclose(best[0], R_true, atol=1e-9)
    np.testing.assert_allclose(best[1] * distance, t_true, atol=1e-8)
    np.testing.assert_allclose(best[2], n_true, atol=1e-9)


def test_python_steps_and_cpp_run_agree() -> None:
    sim = simulate_tracks("paper", None, noise_px=0.5, seed=7)
    driver = RegistrationDriver(sim.tracks, sim.intrinsics)
    driver.run()
    other = RegistrationDriver(sim.tracks, sim.intrinsics)
    summary = other.reconstruction.run()
    assert summary.initialized and summary.refined.rounds >= 1
    np.testing.assert_array_equal(driver.reconstruction.registered, other.reconstruction.registered)
    np.testing.assert_array_equal(driver.reconstruction.active, other.reconstruction.active)
    np.testing.assert_allclose(driver.reconstruction.poses, other.reconstruction.poses, rtol=0, atol=1e-12)


def test_a_caller_can_stop_after_any_step() -> None:
    sim = simulate_tracks("paper", None, noise_px=0.5, seed=8)
    driver = RegistrationDriver(sim.tracks, sim.intrinsics)
    seen = []
    calibration = driver.run(lambda step: seen.append(step.name) or len(seen) < 4)
    assert seen == ["initialize", "adjust", "register", "register"]
    assert len(calibration.registered) == 4
    assert all("not" not in reason for reason in calibration.failed.values())


def test_calibration_round_trips_through_its_files(tmp_path) -> None:
    sim = simulate_tracks("paper", None, noise_px=0.5, seed=9)
    calibration = register(sim.tracks, sim.intrinsics)
    calibration.save(tmp_path)
    loaded = type(calibration).load(tmp_path)
    assert loaded.registered == calibration.registered
    for name in calibration.registered:
        np.testing.assert_allclose(loaded.poses[name][0], calibration.poses[name][0], atol=1e-12)
        np.testing.assert_allclose(loaded.poses[name][1], calibration.poses[name][1], atol=1e-12)
    np.testing.assert_allclose(loaded.points, calibration.points, atol=1e-8)
    assert loaded.metrics == calibration.metrics
    assert loaded.unit == "arbitrary"


def test_rotation_helpers_are_inverse() -> None:
    rng = np.random.default_rng(0)
    for _ in range(50):
        w = rng.normal(size=3)
        w *= rng.uniform(0, np.pi) / np.linalg.norm(w)
        np.testing.assert_allclose(rotvec_from_matrix(matrix_from_rotvec(w)), w, atol=1e-9)


def test_pose_uncertainty_flags_the_close_up_camera_as_weak(tmp_path) -> None:
    """The final bundle adjustment's covariance gives each camera's 1-sigma rotation and
    centre uncertainty: the zoomed camera's is near its Cramer-Rao bound and above the
    weak limit, the others' far below; the written poses carry them, and comparing with
    the truth aligns on the cameras that are not weak."""
    sim = simulate_tracks("or-full", None, noise_px=0.5, seed=0)
    calibration = register(sim.tracks, sim.intrinsics, INDEPENDENT_ERRORS)
    metrics = calibration.metrics
    assert [name for name, m in metrics.items() if m.weak] == ["ceiling"]
    # The bound's covariance is for residuals of unit variance; the noise is 0.5 px.
    predicted = 0.5 * predicted_rotation_sigma_deg(sim, "ceiling", gauge=calibration.registration_order[0],
                                                   model="coplanar")
    assert predicted / 1.5 < metrics["ceiling"].rotation_sigma_deg < 1.5 * predicted
    assert metrics[calibration.registration_order[0]].rotation_sigma_deg == 0.0  # the gauge
    for name, m in metrics.items():
        assert m.centre_sigma is not None and m.centre_sigma >= 0.0, name
        if name != "ceiling":
            assert m.rotation_sigma_deg < RegistrationOptions().weak_rotation_sigma_deg / 5, name
    calibration.save(tmp_path)
    written = json.loads((tmp_path / "camera_poses.json").read_text())["cameras"]
    assert written["ceiling"]["weak"] is True and written["far1"]["weak"] is False
    assert written["ceiling"]["rotation_sigma_deg"] == pytest.approx(metrics["ceiling"].rotation_sigma_deg)
    result = compare(tmp_path / "camera_poses.json", truth_poses(sim))
    strong = [name for name in result.cameras if name != "ceiling"]
    rmse = float(np.sqrt(np.mean([result.cameras[name].rotation_deg ** 2 for name in strong])))
    assert rmse < MAX_ROTATION_RMSE_DEG


def test_a_weak_camera_does_not_pull_the_others() -> None:
    """The zoomed camera's observations biased by +-5 px per point (its own threshold
    grows with them: all stay inliers), two different ways: the joint fit weighs its 57
    observations against thousands, so the other cameras move by a tenth of the rotation
    bound at most (measured 0.0007 deg), while it stays registered and reported weak."""
    sim = simulate_tracks("or-full", None, noise_px=0.5, seed=1)
    tracks = sim.tracks
    on_ceiling = tracks.camera_index == tracks.camera_names.index("ceiling")

    def biased(seed: int) -> Tracks:
        bias = 5.0 * np.random.default_rng(seed).choice([-1.0, 1.0], size=(len(tracks), 2))
        return Tracks.from_observations(tracks.camera_names, tracks.camera_index,
                                        tracks.point_ids[tracks.point_index], tracks.xy + on_ceiling[:, None] * bias,
                                        tracks.markers_per_array)

    first, second = (register(biased(seed), sim.intrinsics, RegistrationOptions()) for seed in (3, 4))
    assert first.metrics["ceiling"].weak and second.metrics["ceiling"].weak
    strong = [name for name in first.poses if name != "ceiling"]
    result = compare(CameraPoses({n: first.poses[n] for n in strong}, first.unit),
                     CameraPoses({n: second.poses[n] for n in strong}, second.unit))
    assert max(result.cameras[name].rotation_deg for name in strong) < 0.1 * MAX_ROTATION_RMSE_DEG


# The projector in the model (ba/projector_cost.h): the demo room, its zoomed ceiling
# camera seeing about 25 centres of a 48-array sequence.
def demo_with_projector(noise_px: float = 0.1, seed: int = 0, projector_dist: tuple[float, float] = (0.0, 0.0),
                        relief: FloorRelief | None = None, projector_moves: dict | None = None):
    from calibproj.sequence.projected import layout_markers
    from calibproj.sequence.layout import MsmLayout
    from calibproj.simulate.scene import load_scene

    layout = MsmLayout(arrays=48)
    scene = load_scene("demo")
    scene = replace(scene, projector=replace(scene.projector, dist=projector_dist, **(projector_moves or {})),
                    floor=replace(scene.floor, relief=relief))
    sim = simulate_tracks(scene, None, noise_px=noise_px, seed=seed, layout=layout)
    return sim, layout_markers(layout)


# Simulated tracks have independent errors: the covariance then needs no share of
# errors common to a camera's centres (RegistrationOptions.error_correlation).
INDEPENDENT_ERRORS = RegistrationOptions(error_correlation=0.0, shared_error_shift=0.0, shared_error_field=0.0)


def rotation_error_deg(calibration, sim, name: str) -> float:
    return compare(CameraPoses(calibration.poses, calibration.unit, calibration.failed), truth_poses(sim)).cameras[name].rotation_deg


@pytest.mark.parametrize("seed", [0, 1])
def test_the_projector_makes_the_zoomed_camera_known_with_an_honest_sigma(seed: int) -> None:
    sim, markers = demo_with_projector(seed=seed)
    without = register(sim.tracks, sim.intrinsics, INDEPENDENT_ERRORS)
    driver = RegistrationDriver(sim.tracks, sim.intrinsics, INDEPENDENT_ERRORS, projector=markers)
    calibration = driver.run()
    assert without.metrics["ceiling"].weak  # too few points to place it from the cameras alone
    error = rotation_error_deg(calibration, sim, "ceiling")
    sigma = calibration.metrics["ceiling"].rotation_sigma_deg
    assert not calibration.metrics["ceiling"].weak
    assert error < 0.5 * rotation_error_deg(without, sim, "ceiling")
    assert error <= 3.0 * sigma
    # The noise each camera shows is the simulated one; the projector's maps are exact
    # here, so their noise is small against the cameras' (in floor terms 0.1 px of a far
    # camera is about 0.3 projector px).
    rec = driver.reconstruction
    np.testing.assert_allclose(rec.camera_sigma_px, 0.1, rtol=0.25)
    assert max(rec.projector_sigma_px) < 0.1
    np.testing.assert_allclose(rec.projector_lens, 0.0, atol=0.01)  # a pinhole projector


def test_a_camera_seeing_a_few_centres_alone_is_registered_through_the_projector() -> None:
    sim, markers = demo_with_projector()
    tracks = sim.tracks
    camera_index, point_index, xy = tracks.bundle_arrays()
    ceiling = tracks.camera_names.index("ceiling")
    own = camera_index == ceiling
    pixels, points = xy[own], point_index[own]
    # Five centres spread over the ceiling camera's image (its corners' nearest and its
    # middle's), and no other camera sees them.
    width, height = sim.intrinsics["ceiling"].resolution
    targets = [(0, 0), (width, 0), (0, height), (width, height), (width / 2, height / 2)]
    keep_points = np.unique([points[np.argmin(np.hypot(*(pixels - target).T))] for target in targets])
    assert len(keep_points) == 5
    drop = (np.isin(point_index, keep_points) & (camera_index != ceiling)) | \
           ((camera_index == ceiling) & ~np.isin(point_index, keep_points))
    sparse = tracks.select(~drop)
    assert (sparse.bundle_arrays()[0] == sparse.camera_names.index("ceiling")).sum() == 5
    without = register(sparse, sim.intrinsics, RegistrationOptions())
    assert "ceiling" in without.failed
    calibration = register(sparse, sim.intrinsics, RegistrationOptions(), projector=markers)
    assert "ceiling" in calibration.registered
    assert calibration.metrics["ceiling"].weak
    error = rotation_error_deg(calibration, sim, "ceiling")
    assert error <= 3.0 * calibration.metrics["ceiling"].rotation_sigma_deg


def test_a_noisier_camera_gets_its_own_noise_and_a_wider_sigma() -> None:
    sim, markers = demo_with_projector(noise_px=0.1)
    tracks = sim.tracks
    camera_index, point_index, xy = tracks.bundle_arrays()
    far2 = tracks.camera_names.index("far2")
    noisy = xy.copy()
    rng = np.random.default_rng(3)
    # 0.1 px as simulated plus 0.3 px more: 0.32 px on far2.
    noisy[camera_index == far2] += rng.normal(scale=0.3, size=(int((camera_index == far2).sum()), 2))
    degraded = Tracks.from_observations(tracks.camera_names, camera_index, np.asarray(tracks.point_ids)[point_index],
                                        noisy, tracks.markers_per_array)
    plain = register(degraded, sim.intrinsics, RegistrationOptions(estimate_noise=False), projector=markers)
    driver = RegistrationDriver(degraded, sim.intrinsics, RegistrationOptions(), projector=markers)
    weighted = driver.run()
    sigma = dict(zip(degraded.camera_names, driver.reconstruction.camera_sigma_px))
    assert sigma["far2"] == pytest.approx(np.hypot(0.1, 0.3), rel=0.15)
    for name in ("far1", "far4", "far5", "near1"):
        assert sigma[name] == pytest.approx(0.1, rel=0.15)
    # Its pose is known as poorly as its centres say: wider than with one noise pooled
    # over all cameras (which its own residuals inflate too), and holding the truth.
    assert weighted.metrics["far2"].rotation_sigma_deg > 1.25 * plain.metrics["far2"].rotation_sigma_deg
    assert rotation_error_deg(weighted, sim, "far2") <= 3.0 * weighted.metrics["far2"].rotation_sigma_deg


def test_the_projector_lens_is_estimated_with_the_maps() -> None:
    # A projector lens throwing the image's corners 30 px outwards (k1 0.05, k2 0.01).
    sim, markers = demo_with_projector(projector_dist=(0.05, 0.01))
    driver = RegistrationDriver(sim.tracks, sim.intrinsics, INDEPENDENT_ERRORS, projector=markers)
    calibration = driver.run()
    rec = driver.reconstruction
    assert rec.projector_lens[0] < -0.01  # undoes a barrel-free, pincushion-like outward throw
    # The maps hold to well under the cameras' noise in floor terms (0.1 px of a far
    # camera is about 0.3 projector px), and the zoomed camera gains as without the lens.
    assert max(rec.projector_sigma_px) < 0.1
    assert not calibration.metrics["ceiling"].weak
    assert rotation_error_deg(calibration, sim, "ceiling") <= 3.0 * calibration.metrics["ceiling"].rotation_sigma_deg


def test_a_table_top_only_the_zoomed_camera_sees_is_placed_on_the_table() -> None:
    """The zoomed ceiling camera of the or-table room looks at the table top; half of its
    centres (the ones at one edge of its view) no other camera sees. One view alone puts
    a point on the floor until the table's plane is found; then the projector tells which
    plane it lies on (across one plane, projector pixels map to the camera's by a
    homography of that plane), and the point goes onto the table top. Left on the floor,
    those points pulled the camera tens of degrees off in a rendered room."""
    from calibproj.sequence.layout import MsmLayout
    from calibproj.sequence.projected import layout_markers

    layout = MsmLayout(arrays=48)
    sim = simulate_tracks("or-table", None, noise_px=0.1, seed=0, layout=layout)
    markers = layout_markers(layout)
    tracks = sim.tracks
    camera_index, point_index, _ = tracks.bundle_arrays()
    ceiling = tracks.camera_names.index("ceiling")
    ids = np.asarray(tracks.point_ids)
    own = np.unique(point_index[camera_index == ceiling])
    assert np.allclose(sim.msm_points[ids[own], 2], 0.9)  # all on the table top
    alone = own[np.argsort(markers.pixels(ids[own])[:, 1])[: len(own) // 2]]
    sparse = tracks.select(~(np.isin(point_index, alone) & (camera_index != ceiling)))
    driver = RegistrationDriver(sparse, sim.intrinsics, RegistrationOptions(model="coplanar"), projector=markers)
    calibration = driver.run()
    top = calibration.planes[0].offset  # the table top, in the calibration's unit
    height = dict(zip(calibration.point_ids, np.asarray(calibration.points)[:, 2]))
    placed = [height[i] for i in ids[alone] if i in height]
    assert len(placed) >= 0.8 * len(alone)
    np.testing.assert_allclose(placed, top, rtol=0.01)
    assert rotation_error_deg(calibration, sim, "ceiling") <= 3.0 * calibration.metrics["ceiling"].rotation_sigma_deg
    # Where the table's placed points surround a projector pixel, the projector draws on
    # the table: no floor point is taken for one of the table's, and most of the table's
    # are (beyond its outermost placed points, such as the centres the zoomed camera
    # alone sees, the outline does not reach).
    rec = driver.reconstruction
    sparse_ids = np.asarray(sparse.point_ids)
    drawn = np.array([rec.projected_plane(p) for p in range(len(sparse_ids))])
    on_top = np.isclose(sim.msm_points[sparse_ids, 2], 0.9)
    assert not np.any(drawn[~on_top] == 1)
    assert np.mean(drawn[on_top] == 1) > 2 / 3


def test_errors_a_camera_shares_widen_its_sigma_to_hold_the_truth() -> None:
    """Each camera's centres carry, besides independent noise (0.05 px), a smooth error
    field of a few hundredths of a pixel (a lens model's or a renderer's residue): the
    pose absorbs part of it and the residuals do not show it. Counted as independent, the
    centres claim sigmas the errors exceed several times; with the default correlation
    every camera's error is within 3 sigma, and the zoomed one is still not weak."""
    sim, markers = demo_with_projector(noise_px=0.05)
    tracks = sim.tracks
    rng = np.random.default_rng(100)
    xy = tracks.xy.copy()
    for c, name in enumerate(tracks.camera_names):
        width, height = sim.intrinsics[name].resolution
        own = tracks.camera_index == c
        u, v = 2.0 * xy[own, 0] / width - 1.0, 2.0 * xy[own, 1] / height - 1.0
        xy[own] += np.column_stack([u * u, u * v, v * v, u, v]) @ rng.normal(scale=0.02, size=(5, 2))
    shifted = tracks.with_xy(xy)

    def error_over_sigma(options: RegistrationOptions) -> tuple[dict[str, float], Calibration]:
        calibration = RegistrationDriver(shifted, sim.intrinsics, options, projector=markers).run()
        ratios = {name: rotation_error_deg(calibration, sim, name) / m.rotation_sigma_deg
                  for name, m in calibration.metrics.items() if m.rotation_sigma_deg > 0}
        return ratios, calibration

    independent, _ = error_over_sigma(INDEPENDENT_ERRORS)
    shared, calibration = error_over_sigma(RegistrationOptions())
    assert max(independent.values()) > 4.0
    assert max(shared.values()) <= 3.0, shared
    assert not calibration.metrics["ceiling"].weak


def errors_to_reference(calibration, sim) -> dict[str, float]:
    """Each camera's rotation error relative to the reference camera (the covariance's
    gauge: its sigma is 0), the reference left out."""
    reference = next(name for name, m in calibration.metrics.items() if m.rotation_sigma_deg == 0.0)
    truth = {camera.name: camera.R for camera in sim.scene.cameras}
    errors = rotation_errors_to_reference(calibration.poses, reference, truth)
    return {name: error for name, error in errors.items() if name != reference}


def with_shared_shifts(sim, shift_px: float, seed: int) -> Tracks:
    """sim's tracks with each camera's centres moved by one shift (the form
    RegistrationOptions.shared_error_shift models), drawn with standard deviation
    shift_px along each image axis."""
    tracks = sim.tracks
    xy = tracks.xy + np.random.default_rng(seed).normal(scale=shift_px, size=(len(tracks.camera_names), 2))[
        tracks.camera_index]
    return tracks.with_xy(xy)


def test_a_shift_each_camera_shares_is_propagated_into_every_pose() -> None:
    """Each camera's centres carry independent noise (0.05 px) and a shift of their own,
    twice that (a new one each run, the same room). Counted as independent, the errors
    exceed the sigmas several times; with shared_error_shift 2 the sigmas hold them: over
    the runs and cameras their ratio's root mean square is near 1, not far below (a
    covariance that only widened would pass the first test, not this one). Measured: 1.46
    (largest 2.7), where the discount of every camera's residuals gives 2.8 (6.0) and
    independent errors 8.3 (17.6)."""
    sim, markers = demo_with_projector(noise_px=0.05)
    shifts = RegistrationOptions(error_correlation=0.0, shared_error_shift=2.0)
    ratios, independent = [], []
    for run in range(4):
        moved = with_shared_shifts(sim, 0.1, seed=200 + run)
        for options, out in ((shifts, ratios), (INDEPENDENT_ERRORS, independent)):
            calibration = RegistrationDriver(moved, sim.intrinsics, options, projector=markers).run()
            errors = errors_to_reference(calibration, sim)
            out.extend(errors[name] / calibration.metrics[name].rotation_sigma_deg for name in errors)
    rms_ratio = float(np.sqrt(np.mean(np.square(ratios))))
    assert 0.5 <= rms_ratio <= 1.75, ratios
    assert max(ratios) <= 3.5, ratios
    assert float(np.sqrt(np.mean(np.square(independent)))) > 2.0 * rms_ratio


def test_an_uneven_floor_is_not_taken_for_the_zoomed_cameras_tilt() -> None:
    """A floor 3 mm (rms) uneven, as real floors are: the zoomed ceiling camera sees a
    patch half a metre wide, whose slope (about 0.7 deg) an exactly flat model gives it
    as its own tilt, several sigma off; with the floor's relief in the model its sigma
    holds the truth, and the cameras that see the floor from the side are better too."""
    sim, markers = demo_with_projector(noise_px=0.05, relief=FloorRelief(rms_m=0.003, seed=1))

    def calibrated(floor_relief: float) -> tuple[dict[str, float], Calibration]:
        """Errors relative to the reference camera, which its covariance's are."""
        options = replace(INDEPENDENT_ERRORS, floor_relief=floor_relief)
        calibration = RegistrationDriver(sim.tracks, sim.intrinsics, options, projector=markers).run()
        assert sorted(calibration.registered) == sorted(sim.tracks.camera_names)
        return errors_to_reference(calibration, sim), calibration

    flat_errors, flat = calibrated(0.0)
    errors, calibration = calibrated(RegistrationOptions().floor_relief)
    # Measured (relative to the reference camera): when flat, ceiling 0.58 deg against a
    # sigma of 0.070 and near1 0.060 against 0.009; with the relief, ceiling 0.15
    # against 0.066, every other camera within 0.006 deg and 2.1 sigma.
    assert flat_errors["ceiling"] > 3.0 * flat.metrics["ceiling"].rotation_sigma_deg
    for name, error in errors.items():
        assert error <= 3.0 * calibration.metrics[name].rotation_sigma_deg, name
    others = [name for name in errors if name != "ceiling"]
    assert max(errors[n] for n in others) < max(flat_errors[n] for n in others)
    assert calibration.floor_rms > 0.001  # the relief was detected and estimated


def test_a_shared_error_field_widens_the_zoomed_cameras_sigma_on_an_uneven_floor() -> None:
    """Each camera's shared errors as a smooth field over its image (independent shifts
    at a 3 x 3 grid's nodes) are propagated into the covariance only: the poses stay
    where they are and every sigma widens. (On rendered rooms with a floor 6 mm uneven the
    zoomed camera's widens 2.2x, README; here its sigma is its few centres' own.)"""
    sim, markers = demo_with_projector(noise_px=0.05, relief=FloorRelief(rms_m=0.006, seed=1))

    def calibrated(field: float) -> Calibration:
        options = RegistrationOptions(shared_error_field=field)
        return RegistrationDriver(sim.tracks, sim.intrinsics, options, projector=markers).run()
    without, with_field = calibrated(0.0), calibrated(0.75)
    widened = {}
    for name, (R, t) in without.poses.items():
        np.testing.assert_allclose(with_field.poses[name][0], R, atol=1e-12)
        np.testing.assert_allclose(with_field.poses[name][1], t, atol=1e-12)
        sigma = without.metrics[name].rotation_sigma_deg
        if sigma > 0.0:  # not the reference camera
            widened[name] = with_field.metrics[name].rotation_sigma_deg / sigma
    assert min(widened.values()) > 1.0, widened
    with pytest.raises(ValueError, match="shared_error_field"):
        RegistrationOptions(shared_error_field=-1.0)


def test_the_relief_places_the_projector_where_it_hangs() -> None:
    """The projector sees a centre that the floor's relief raises along its ray, not
    straight down, so the relief's parallax places the projector's optical centre. Hung
    at 3.6 m (the highest camera, the prior's guess, is at 2.95 m) and tilted by 6 deg
    (its nadir 0.38 m from the middle of the projection, the prior's other guess), it is
    found where it hangs."""
    position, look_at = (0.2, -0.1, 3.6), (0.58, -0.1, 0.0)
    sim, markers = demo_with_projector(noise_px=0.05, relief=FloorRelief(rms_m=0.006, seed=2),
                                       projector_moves={"position": position, "look_at": look_at})
    driver = RegistrationDriver(sim.tracks, sim.intrinsics, INDEPENDENT_ERRORS, projector=markers)
    driver.run()
    reconstruction = driver.reconstruction
    plane = np.asarray(reconstruction.plane)
    normal = plane[:3] / np.linalg.norm(plane[:3])
    offset = plane[3] / np.linalg.norm(plane[:3])

    def height_and_foot(point: np.ndarray) -> tuple[float, np.ndarray]:
        height = float(normal @ point - offset)
        return height, point - height * normal

    names = sim.tracks.camera_names
    centres = {}
    for k, name in enumerate(names):
        pose = np.asarray(reconstruction.poses)[k]
        centres[name] = -matrix_from_rotvec(pose[:3]).T @ pose[3:]
    ceiling_height, ceiling_foot = height_and_foot(centres["ceiling"])
    projector_height, projector_foot = height_and_foot(np.asarray(reconstruction.projector_centre))
    truth = {camera.name: np.asarray(camera.center) for camera in sim.scene.cameras}
    true_projector = np.asarray(position)
    # In units of the ceiling camera's height: the calibration's own unit is arbitrary.
    # Measured: height 1.2195 against 1.2203; the feet's distances within 0.0022 (6 mm).
    assert projector_height / ceiling_height == pytest.approx(true_projector[2] / truth["ceiling"][2], rel=0.01)
    for name in ("ceiling", "far1", "near1"):
        _, foot = height_and_foot(centres[name])
        found = np.linalg.norm(projector_foot - foot) / abs(ceiling_height)
        expected = np.linalg.norm(true_projector[:2] - truth[name][:2]) / truth["ceiling"][2]
        assert found == pytest.approx(expected, abs=0.01), name


@pytest.mark.parametrize("cubic", [False, True])
def test_the_relief_grid_has_the_cells_asked_for(caplog, cubic: bool) -> None:
    sim, markers = demo_with_projector(noise_px=0.05, relief=FloorRelief(rms_m=0.003, seed=1))
    nodes = {}
    for cells in (8, 24):
        caplog.clear()
        with caplog.at_level(logging.INFO, logger="calibproj.registration.driver"):
            options = replace(INDEPENDENT_ERRORS, relief_cells=cells, relief_cubic=cubic)
            RegistrationDriver(sim.tracks, sim.intrinsics, options, projector=markers).run()
        found = re.search(r"over its (\d+) nodes", caplog.text)
        assert found, caplog.text
        nodes[cells] = int(found.group(1))
    # The test of unevenness is on a grid half as fine, with (cells / 2 + 1) nodes along
    # the longer extent, fewer along the other; a cubic relief has a ring of control
    # points around the cells besides (cells / 2 + 3).
    ring = 2 if cubic else 0
    assert (5 + ring) * (2 + ring) <= nodes[8] <= (5 + ring) ** 2, nodes
    assert (13 + ring) * (4 + ring) <= nodes[24] <= (13 + ring) ** 2, nodes
    with pytest.raises(ValueError, match="relief_cells"):
        RegistrationOptions(relief_cells=33)


def test_a_flat_floor_keeps_the_flat_model_and_its_sigma(caplog) -> None:
    """On a floor flat within the noise the relief explains nothing the noise would not
    (the likelihood-ratio test of the core's Refine): the floor is kept exactly flat, so
    the zoomed camera's sigma is the flat model's, several times narrower than with a
    relief it would have to share its tilt with."""
    sim, markers = demo_with_projector(noise_px=0.05, seed=3)

    def calibrated(floor_relief: float) -> Calibration:
        options = replace(INDEPENDENT_ERRORS, floor_relief=floor_relief)
        return RegistrationDriver(sim.tracks, sim.intrinsics, options, projector=markers).run()

    flat = calibrated(0.0)
    with caplog.at_level(logging.INFO, logger="calibproj.registration.driver"):
        tested = calibrated(RegistrationOptions().floor_relief)
    assert "floor flat within the noise: kept exactly flat" in caplog.text
    assert tested.floor_rms < 1e-9
    for name, metrics in tested.metrics.items():
        assert metrics.rotation_sigma_deg == pytest.approx(flat.metrics[name].rotation_sigma_deg, rel=1e-6), name
    assert not tested.metrics["ceiling"].weak


def with_shared_fields(tracks: Tracks, amplitude_px: float, waves: float, seed: int) -> Tracks:
    """``tracks`` with a smooth error field over each camera's image added, as blur, a
    lens model or a floor's texture leave in real detections: per axis two sine waves of
    random phase, ``amplitude_px`` each, ``waves`` half periods across 1280 px."""
    rng = np.random.default_rng(seed)
    xy = np.array(tracks.xy, dtype=float)
    for camera in range(len(tracks.camera_names)):
        rows = np.asarray(tracks.camera_index) == camera
        scaled = xy[rows] / 1280.0 * np.pi * waves
        for axis in range(2):
            phases = rng.uniform(0.0, 2.0 * np.pi, 2)
            xy[rows, axis] += amplitude_px * (np.sin(scaled[:, 0] + phases[0]) + np.sin(scaled[:, 1] + phases[1]))
    return Tracks.from_observations(list(tracks.camera_names), np.asarray(tracks.camera_index),
                                    np.asarray(tracks.point_ids)[np.asarray(tracks.point_index)], xy,
                                    tracks.markers_per_array)


def relief_test(tracks: Tracks, intrinsics, markers) -> tuple:
    """The registration's calibration and its relief test (the refinement's ReliefTest)."""
    refined = []
    calibration = RegistrationDriver(tracks, intrinsics, RegistrationOptions(), projector=markers).run(
        lambda step: refined.append(step.result) if step.name == "refine" else None)
    return calibration, refined[0].relief


def test_errors_the_cameras_share_do_not_pass_for_a_relief() -> None:
    """Each camera's detection errors share a smooth field; on a flat floor a relief takes
    some of it up, more than independent noise would (above the chi-square's 99.9 %
    quantile, a quarter of the bar, as the rendered flat floors did: 100-370 against
    154), but less than the bar: the floor stays flat. A floor 1 mm uneven with the same
    errors is found uneven."""
    sim, markers = demo_with_projector(noise_px=0.05, seed=3)
    flat, test = relief_test(with_shared_fields(sim.tracks, 0.04, waves=4.0, seed=5), sim.intrinsics, markers)
    assert test.tested and test.threshold_chi2 / 4.0 < test.gain_chi2 < test.threshold_chi2
    assert not test.detected and flat.floor_rms < 1e-9
    uneven, _ = demo_with_projector(noise_px=0.05, seed=3, relief=FloorRelief(rms_m=0.001, seed=1))
    _, test = relief_test(with_shared_fields(uneven.tracks, 0.04, waves=4.0, seed=5), uneven.intrinsics, markers)
    assert test.detected and test.gain_chi2 > 10.0 * test.threshold_chi2
