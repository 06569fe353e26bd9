"""Bundle adjustment on the paper's synthetic ring rig, covariance, and input validation."""

from __future__ import annotations

import numpy as np
import pytest

from calibproj import _core
from calibproj.simulate.synthetic import paper_ring_rig, perturb_poses

ba = _core.ba


@pytest.fixture(scope="module")
def rig():
    return paper_ring_rig(seed=4, noise_px=0.5)


def solve(problem, poses, points, plane, **options):
    return ba.bundle_adjust(
        problem.camera_index, problem.point_index, problem.observed, problem.K, poses, points, plane, **options
    )


def perturbed_start(problem, seed: int):
    rng = np.random.default_rng(seed)
    poses = perturb_poses(problem.poses, rotation_deg=2.0, translation_m=0.05, rng=rng)
    points = problem.points + rng.normal(0.0, 0.05, problem.points.shape)
    plane = np.array([0.02, -0.03, 1.0, 0.04])
    return poses, points, plane


@pytest.mark.parametrize("model", ["free", "coplanar"])
def test_perturbed_start_reaches_the_cost_of_the_true_start(rig, model: str) -> None:
    from_truth = solve(rig, rig.poses, rig.points, rig.plane, model=model)
    poses, points, plane = perturbed_start(rig, seed=1)
    from_perturbed = solve(rig, poses, points, plane, model=model)
    assert from_truth.usable and from_perturbed.usable
    assert from_perturbed.initial_cost > 100.0 * from_perturbed.final_cost
    relative = abs(from_perturbed.final_cost - from_truth.final_cost) / from_truth.final_cost
    assert relative < 1e-6
    # 0.5 px noise: the mean squared residual per coordinate is about 0.25 less the
    # share of degrees of freedom absorbed by the parameters.
    mean_square = np.mean(from_perturbed.residuals ** 2)
    assert 0.15 < mean_square < 0.25


def test_coplanar_points_lie_on_the_refined_plane(rig) -> None:
    poses, points, plane = perturbed_start(rig, seed=2)
    result = solve(rig, poses, points, plane, model="coplanar")
    n, d = result.plane[:3], result.plane[3]
    assert abs(np.linalg.norm(n) - 1.0) < 1e-12
    assert np.max(np.abs(result.points @ n - d)) < 1e-9
    # The caller's orientation of the normal is kept.
    assert n @ plane[:3] > 0


@pytest.mark.parametrize("model", ["free", "coplanar"])
def test_gauge_camera_and_scale_are_held(rig, model: str) -> None:
    poses, points, plane = perturbed_start(rig, seed=3)
    result = solve(rig, poses, points, plane, model=model, gauge_camera=2)
    np.testing.assert_array_equal(result.poses[2], poses[2])

    def centre(pose):
        from calibproj.simulate.synthetic import matrix_from_rotvec

        return -matrix_from_rotvec(pose[:3]).T @ pose[3:]

    if model == "free":
        s = result.scale_camera
        before = np.linalg.norm(centre(poses[s]) - centre(poses[2]))
        after = np.linalg.norm(centre(result.poses[s]) - centre(result.poses[2]))
        assert abs(after - before) < 1e-9 * before
    else:
        n = plane[:3] / np.linalg.norm(plane[:3])
        before = abs(n @ centre(poses[2]) - plane[3] / np.linalg.norm(plane[:3]))
        after = abs(result.plane[:3] @ centre(result.poses[2]) - result.plane[3])
        assert abs(after - before) < 1e-9 * before


@pytest.mark.parametrize("model", ["free", "coplanar"])
def test_pose_covariance_is_symmetric_positive_definite(rig, model: str) -> None:
    result = solve(rig, rig.poses, rig.points, rig.plane, model=model, compute_covariance=True)
    covariances = result.pose_covariances
    assert covariances.shape == (len(rig.poses), 6, 6)
    assert np.all(np.isfinite(covariances))
    np.testing.assert_array_equal(covariances[0], np.zeros((6, 6)))  # the gauge camera
    for c in range(1, len(rig.poses)):
        sigma = covariances[c]
        np.testing.assert_allclose(sigma, sigma.T, rtol=1e-9, atol=1e-18)
        eigenvalues = np.linalg.eigvalsh(sigma)
        if model == "free" and c == result.scale_camera:
            # One direction (the distance to the gauge camera) is fixed by the gauge.
            assert eigenvalues[0] < 1e-9 * eigenvalues[-1] and eigenvalues[1] > 0
        else:
            assert eigenvalues[0] > 0
        # Rotation uncertainty of a 0.5 px rig: a few thousandths of a degree.
        assert np.sqrt(np.max(np.diag(sigma)[:3])) < np.deg2rad(0.05)


def _pose_deltas(poses: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """[dtheta, dt] per camera with R = Exp(dtheta) R_reference, t = t_reference + dt."""
    from calibproj.simulate.synthetic import matrix_from_rotvec, rotvec_from_matrix

    deltas = []
    for pose, ref in zip(poses, reference):
        rotation = matrix_from_rotvec(pose[:3]) @ matrix_from_rotvec(ref[:3]).T
        deltas.append(np.concatenate([rotvec_from_matrix(rotation), pose[3:] - ref[3:]]))
    return np.concatenate(deltas)


@pytest.mark.parametrize("model", ["free", "coplanar"])
def test_joint_pose_covariance_matches_the_spread_of_re_noised_solutions(model: str) -> None:
    """The reduced camera system's joint covariance, cross terms included, against 300
    solutions of the same rig with fresh 0.5 px noise: each camera's rotation and
    translation variance and the relative rotation of camera pairs (which only the
    cross terms get right) within 25 %."""
    clean = paper_ring_rig(seed=5, noise_px=0.0, num_points=150)
    sigma = 0.5
    nominal = solve(clean, clean.poses, clean.points, clean.plane, model=model, compute_covariance=True)
    predicted = sigma**2 * nominal.pose_covariance
    np.testing.assert_allclose(np.diagonal(predicted.reshape(len(clean.poses), 6, len(clean.poses), 6),
                                           axis1=0, axis2=2).transpose(2, 0, 1),
                               sigma**2 * nominal.pose_covariances, rtol=1e-12, atol=1e-20)
    rng = np.random.default_rng(11)
    samples = []
    for _ in range(300):
        noisy = clean.observed + rng.normal(0.0, sigma, clean.observed.shape)
        result = ba.bundle_adjust(clean.camera_index, clean.point_index, noisy, clean.K, clean.poses, clean.points,
                                  clean.plane, model=model)
        samples.append(_pose_deltas(result.poses, clean.poses))
    empirical = np.cov(np.array(samples).T)
    cameras = range(1, len(clean.poses))
    for c in cameras:
        for axis in (slice(0, 3), slice(3, 6)):
            rows = np.arange(6 * c, 6 * c + 6)[axis]
            ratio = np.trace(empirical[np.ix_(rows, rows)]) / np.trace(predicted[np.ix_(rows, rows)])
            assert 0.75 < ratio < 1.25, (c, axis, ratio)
    for a, b in ((1, 2), (3, 7), (6, 9)):
        difference = np.zeros(6 * len(clean.poses))
        difference[6 * a:6 * a + 3], difference[6 * b:6 * b + 3] = 1.0, -1.0
        with_cross = difference @ predicted @ difference
        blocks_only = predicted[6 * a:6 * a + 3, 6 * a:6 * a + 3].trace() + predicted[6 * b:6 * b + 3, 6 * b:6 * b + 3].trace()
        ratio = (difference @ empirical @ difference) / with_cross
        assert 0.75 < ratio < 1.25, (a, b, ratio)
        assert abs(with_cross / blocks_only - 1.0) > 0.1  # the cross terms matter here


def test_robust_losses_and_linear_solvers_agree_on_clean_data(rig) -> None:
    reference = solve(rig, rig.poses, rig.points, rig.plane)
    for linear_solver in ("dense_schur", "sparse_schur", "iterative_schur"):
        result = solve(rig, rig.poses, rig.points, rig.plane, linear_solver=linear_solver)
        assert abs(result.final_cost - reference.final_cost) < 1e-7 * reference.final_cost
    huber = solve(rig, rig.poses, rig.points, rig.plane, loss="huber", loss_scale=3.0)
    np.testing.assert_allclose(huber.poses, reference.poses, atol=1e-6)


def test_fixed_poses_refine_points_only(rig) -> None:
    rng = np.random.default_rng(8)
    points = rig.points + rng.normal(0.0, 0.02, rig.points.shape)
    result = solve(rig, rig.poses, points, rig.plane, refine_poses=False)
    np.testing.assert_array_equal(result.poses, rig.poses)
    assert np.sqrt(np.mean(np.sum((result.points - rig.points) ** 2, axis=1))) < 2e-3


def test_fixed_points_refine_poses_only(rig) -> None:
    rng = np.random.default_rng(9)
    poses = perturb_poses(rig.poses, 1.0, 0.03, rng)
    result = solve(rig, poses, rig.points, rig.plane, refine_points=False)
    np.testing.assert_array_equal(result.points, rig.points)
    np.testing.assert_allclose(result.poses, rig.poses, atol=2e-3)


def small_problem():
    rig = paper_ring_rig(seed=1, num_points=60)
    return dict(
        camera_index=rig.camera_index.copy(),
        point_index=rig.point_index.copy(),
        observed=rig.observed.copy(),
        intrinsics=rig.K.copy(),
        poses=rig.poses.copy(),
        points=rig.points.copy(),
    )


def with_change(**changes):
    args = small_problem()
    args.update(changes)
    return args


def bad_inputs():
    args = small_problem()
    n = len(args["camera_index"])
    nan_pixel = args["observed"].copy()
    nan_pixel[3, 1] = np.nan
    inf_pose = args["poses"].copy()
    inf_pose[1, 4] = np.inf
    behind = args["points"].copy()
    behind[0] = [0.0, 0.0, 50.0]  # above every camera
    unused_camera = np.concatenate([args["intrinsics"], args["intrinsics"][:1]])
    unused_pose = np.concatenate([args["poses"], args["poses"][:1]])
    unused_point = np.concatenate([args["points"], [[0.0, 0.0, 0.0]]])
    bad_camera = args["camera_index"].copy()
    bad_camera[5] = 99
    bad_point = args["point_index"].copy()
    bad_point[7] = -1
    return [
        ("mismatched lengths", with_change(point_index=args["point_index"][:-1]), "point indices"),
        ("mismatched pixels", with_change(observed=args["observed"][:-2]), "pixels"),
        ("camera index out of range", with_change(camera_index=bad_camera), "camera index 99 out of range"),
        ("point index out of range", with_change(point_index=bad_point), "point index -1 out of range"),
        ("non-finite pixel", with_change(observed=nan_pixel), "non-finite"),
        ("non-finite pose", with_change(poses=inf_pose), "non-finite"),
        ("empty problem", with_change(camera_index=np.zeros(0, int), point_index=np.zeros(0, int),
                                      observed=np.zeros((0, 2))), "empty problem"),
        ("camera without observation", with_change(intrinsics=unused_camera, poses=unused_pose),
         f"camera {len(args['poses'])} has no observation"),
        ("point without observation", with_change(points=unused_point),
         f"point {len(args['points'])} has no observation"),
        ("point behind a camera", with_change(points=behind), "behind camera"),
        ("intrinsics count", with_change(intrinsics=args["intrinsics"][:-1]), "intrinsics"),
        ("bad pose shape", with_change(poses=args["poses"][:, :5]), "poses"),
    ] + [("observation count", with_change(observed=np.zeros((n, 3))), "observed")]


@pytest.mark.parametrize("name,args,message", bad_inputs(), ids=[case[0] for case in bad_inputs()])
def test_bad_input_raises_value_error(name: str, args: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        ba.bundle_adjust(**args)


@pytest.mark.parametrize(
    "options,message",
    [
        (dict(model="planar"), "unknown value 'planar'"),
        (dict(loss="tukey"), "unknown value 'tukey'"),
        (dict(loss_scale=-1.0), "loss scale"),
        (dict(num_threads=0), "num_threads"),
        (dict(gauge_camera=42), "gauge camera 42"),
        (dict(refine_poses=False, refine_points=False), "nothing to refine"),
    ],
)
def test_bad_options_raise_value_error(options: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        ba.bundle_adjust(**small_problem(), **options)


@pytest.mark.parametrize("model", ["free", "coplanar"])
def test_rotation_cache_changes_nothing(rig, model: str) -> None:
    poses, points, plane = perturbed_start(rig, seed=12)
    cached = solve(rig, poses, points, plane, model=model, cache_rotations=True)
    plain = solve(rig, poses, points, plane, model=model, cache_rotations=False)
    assert cached.iterations == plain.iterations
    np.testing.assert_array_equal(cached.poses, plain.poses)
    np.testing.assert_array_equal(cached.points, plain.points)


def test_piecewise_planar_recovers_a_table_top_and_free_points() -> None:
    """COPLANAR with a second plane (a table top 0.9 m up) and some points off both
    (free 3D points): from perturbed poses, points and planes, noise-free observations
    give back the truth (the gauge camera's pose and the floor's offset fix the frame)."""
    from calibproj.simulate.synthetic import project

    rig = paper_ring_rig(seed=5, noise_px=0.0, num_points=800)
    points = rig.points.copy()
    on_table = (np.abs(points[:, 0]) < 0.8) & (np.abs(points[:, 1]) < 0.4)
    points[on_table, 2] = 0.9
    free = np.flatnonzero(~on_table)[::20]
    points[free, 2] = np.random.default_rng(1).uniform(0.2, 1.5, len(free))
    point_plane = np.where(on_table, 1, 0)
    point_plane[free] = -1
    observed = np.zeros_like(rig.observed)
    for c in range(len(rig.poses)):
        rows = rig.camera_index == c
        observed[rows] = project(rig.K[c], rig.poses[c], points[rig.point_index[rows]])[0]
    rng = np.random.default_rng(2)
    poses = perturb_poses(rig.poses, rotation_deg=1.0, translation_m=0.03, rng=rng)
    poses[0] = rig.poses[0]
    start = points + rng.normal(0.0, 0.03, points.shape)
    result = ba.bundle_adjust(rig.camera_index, rig.point_index, observed, rig.K, poses, start, rig.plane,
                              model="coplanar", more_planes=np.array([[0.02, -0.01, 1.0, 0.93]]),
                              point_plane=point_plane, max_iterations=200)
    assert result.usable and result.final_cost < 1e-12
    np.testing.assert_allclose(result.more_planes[0], [0.0, 0.0, 1.0, 0.9], atol=1e-7)
    np.testing.assert_allclose(result.points, points, atol=1e-7)
    np.testing.assert_allclose(result.poses, rig.poses, atol=1e-7)
    # Bad plane assignments are one clear error.
    with pytest.raises(ValueError, match="plane 2 out of range"):
        ba.bundle_adjust(rig.camera_index, rig.point_index, observed, rig.K, poses, start, rig.plane,
                         model="coplanar", more_planes=np.array([[0.0, 0.0, 1.0, 0.9]]),
                         point_plane=np.full(len(points), 2))
