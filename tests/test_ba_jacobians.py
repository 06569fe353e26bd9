"""Analytic Jacobians of the reprojection costs and the manifolds against numeric ones.

The numeric reference differentiates an independent numpy implementation of the same
residual by central differences (step 1e-6 relative), whose truncation error is about
1e-10 relative: far below the 1e-6 tolerance.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibproj import _core
from calibproj.simulate.synthetic import matrix_from_rotvec

ba = _core.ba
K = np.array([[917.0, 0.3, 959.5], [0.0, 915.0, 539.5], [0.0, 0.0, 1.0]])
TOLERANCE = 1e-6


def reference_residual(pose: np.ndarray, X: np.ndarray, observed: np.ndarray) -> np.ndarray:
    p = matrix_from_rotvec(pose[:3]) @ X + pose[3:]
    uv = K @ (p / p[2])
    return uv[:2] - observed


def householder_basis(n: np.ndarray) -> np.ndarray:
    v = n + np.array([0.0, 0.0, 1.0])
    H = np.eye(3) - np.outer(v, v) / (1.0 + n[2])
    return H[:, :2]


def plane_point(plane: np.ndarray, ab: np.ndarray) -> np.ndarray:
    return plane[3] * plane[:3] + householder_basis(plane[:3]) @ ab


def numeric_jacobian(f, x: np.ndarray, rel_step: float = 1e-6) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    h = rel_step * max(1.0, float(np.linalg.norm(x)))
    columns = []
    for i in range(len(x)):
        step = np.zeros_like(x)
        step[i] = h
        columns.append((f(x + step) - f(x - step)) / (2.0 * h))
    return np.column_stack(columns)


def relative_error(analytic: np.ndarray, numeric: np.ndarray) -> float:
    return float(np.linalg.norm(analytic - numeric) / max(np.linalg.norm(numeric), 1e-12))


def random_rotvec(rng: np.random.Generator, angle: float) -> np.ndarray:
    axis = rng.normal(size=3)
    return angle * axis / np.linalg.norm(axis)


def camera_looking_at(rng: np.random.Generator, target: np.ndarray, rotation_angle: float) -> np.ndarray:
    """A pose with rotation of the given angle whose camera sees ``target`` 3 m ahead."""
    w = random_rotvec(rng, rotation_angle)
    R = matrix_from_rotvec(w)
    in_camera = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3), 3.0])
    return np.concatenate([w, in_camera - R @ target])


# Rotation angles covering the identity (Taylor branch), small, generic and near pi.
ANGLES = [0.0, 1e-9, 1e-6, 1e-3, 0.3, 1.5, 3.0, np.pi - 1e-3]


@pytest.mark.parametrize("angle", ANGLES)
def test_free_cost_jacobians_match_numeric(angle: float) -> None:
    rng = np.random.default_rng(int(angle * 1e6) % 2**32)
    for _ in range(20):
        X = rng.normal(size=3)
        pose = camera_looking_at(rng, X, angle)
        observed = rng.uniform([0, 0], [1920, 1080])
        ok, residual, (J_pose, J_point) = ba.evaluate_free_cost(K, observed, pose, X, [True, True])
        assert ok
        np.testing.assert_allclose(residual, reference_residual(pose, X, observed), rtol=1e-10, atol=1e-8)
        assert relative_error(J_pose, numeric_jacobian(lambda p: reference_residual(p, X, observed), pose)) < TOLERANCE
        assert relative_error(J_point, numeric_jacobian(lambda x: reference_residual(pose, x, observed), X)) < TOLERANCE


def grazing_configuration(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A camera 1.5 m above a plane looking at it at 80-89 degrees from its normal."""
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    if n[2] < 0:
        n = -n
    d = rng.uniform(0.5, 2.0)
    tilt = np.deg2rad(rng.uniform(80.0, 89.0))
    tangent = householder_basis(n)[:, 0]
    X = d * n + 2.0 * tangent
    # Centre 1.5 m off the plane, looking at X along a ray making angle `tilt` with n.
    direction = np.cos(tilt) * n + np.sin(tilt) * tangent
    centre = X - (1.5 / np.cos(tilt)) * direction
    forward = (X - centre) / np.linalg.norm(X - centre)
    right = np.cross(forward, n)
    right /= np.linalg.norm(right)
    R = np.stack([right, np.cross(forward, right), forward])
    from calibproj.simulate.synthetic import rotvec_from_matrix

    pose = np.concatenate([rotvec_from_matrix(R), -R @ centre])
    ab = householder_basis(n).T @ (X - d * n)
    return pose, np.concatenate([n, [d]]), ab


@pytest.mark.parametrize("angle", ANGLES)
def test_plane_cost_jacobians_match_numeric(angle: float) -> None:
    rng = np.random.default_rng(1000 + int(angle * 1e6) % 2**32)
    for _ in range(20):
        n = rng.normal(size=3)
        n[2] = abs(n[2]) + 0.2
        n /= np.linalg.norm(n)
        plane = np.concatenate([n, [rng.uniform(0.5, 3.0)]])
        ab = rng.normal(size=2)
        X = plane_point(plane, ab)
        pose = camera_looking_at(rng, X, angle)
        check_plane_cost(pose, plane, ab, rng.uniform([0, 0], [1920, 1080]))


def test_plane_cost_jacobians_at_grazing_angles() -> None:
    rng = np.random.default_rng(7)
    for _ in range(50):
        pose, plane, ab = grazing_configuration(rng)
        check_plane_cost(pose, plane, ab, rng.uniform([0, 0], [1920, 1080]))
        X = plane_point(plane, ab)
        ok, _, (J_pose, J_point) = ba.evaluate_free_cost(K, np.zeros(2), pose, X, [True, True])
        assert ok
        assert relative_error(J_point, numeric_jacobian(lambda x: reference_residual(pose, x, np.zeros(2)), X)) < TOLERANCE


def check_plane_cost(pose: np.ndarray, plane: np.ndarray, ab: np.ndarray, observed: np.ndarray) -> None:
    ok, residual, (J_pose, J_plane, J_ab) = ba.evaluate_plane_cost(K, observed, pose, plane, ab, [True, True, True])
    assert ok
    X = plane_point(plane, ab)
    assert abs(plane[:3] @ X - plane[3]) < 1e-12
    np.testing.assert_allclose(ba.point_on_plane(plane, ab), X, atol=1e-12)
    np.testing.assert_allclose(residual, reference_residual(pose, X, observed), rtol=1e-10, atol=1e-8)
    f_pose = lambda p: reference_residual(p, X, observed)  # noqa: E731
    f_plane = lambda q: reference_residual(pose, plane_point(q, ab), observed)  # noqa: E731
    f_ab = lambda x: reference_residual(pose, plane_point(plane, x), observed)  # noqa: E731
    assert relative_error(J_pose, numeric_jacobian(f_pose, pose)) < TOLERANCE
    assert relative_error(J_plane, numeric_jacobian(f_plane, plane)) < TOLERANCE
    assert relative_error(J_ab, numeric_jacobian(f_ab, ab)) < TOLERANCE


def test_null_jacobian_blocks_give_the_same_values() -> None:
    rng = np.random.default_rng(3)
    X = rng.normal(size=3)
    pose = camera_looking_at(rng, X, 0.7)
    observed = np.array([100.0, 200.0])
    _, r_all, (J_pose, J_point) = ba.evaluate_free_cost(K, observed, pose, X, [True, True])
    for want in ([False, False], [True, False], [False, True]):
        _, r, jacobians = ba.evaluate_free_cost(K, observed, pose, X, want)
        np.testing.assert_array_equal(r, r_all)
        for flag, J, J_ref in zip(want, jacobians, (J_pose, J_point)):
            assert (J is None) != flag
            if flag:
                np.testing.assert_array_equal(J, J_ref)
    plane = np.array([0.0, 0.6, 0.8, 1.0])
    ab = np.array([0.1, -0.2])
    _, r_all, J_all = ba.evaluate_plane_cost(K, observed, pose, plane, ab, [True, True, True])
    for mask in range(8):
        want = [bool(mask & 1), bool(mask & 2), bool(mask & 4)]
        _, r, jacobians = ba.evaluate_plane_cost(K, observed, pose, plane, ab, want)
        np.testing.assert_array_equal(r, r_all)
        for flag, J, J_ref in zip(want, jacobians, J_all):
            if flag:
                np.testing.assert_array_equal(J, J_ref)
            else:
                assert J is None


def test_point_behind_camera_is_rejected() -> None:
    pose = np.zeros(6)
    ok, _, _ = ba.evaluate_free_cost(K, np.zeros(2), pose, np.array([0.0, 0.0, -1.0]), [True, True])
    assert not ok


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def manifold_cases(rng: np.random.Generator):
    """(name, functions(x, y, delta), x, tangent size, sample of a nearby y)."""
    for fix_offset in (False, True):
        reference = unit(rng.normal(size=3))
        x = np.concatenate([unit(reference + 0.3 * rng.normal(size=3)), [rng.uniform(0.5, 3.0)]])
        size = 2 if fix_offset else 3

        def functions(x_, y_, delta_, reference=reference, fix_offset=fix_offset):
            return ba.plane_manifold(reference, fix_offset, x_, y_, delta_)

        yield f"plane(fix_offset={fix_offset})", functions, x, size
    reference = rng.normal(size=3)
    x = np.concatenate([rng.normal(size=3), reference + 0.2 * rng.normal(size=3)])

    def pose_functions(x_, y_, delta_, reference=reference):
        return ba.fixed_distance_pose_manifold(reference, x_, y_, delta_)

    yield "fixed-distance pose", pose_functions, x, 5


def test_manifolds_satisfy_ceres_invariants() -> None:
    """The invariants listed in ceres/manifold.h, checked on random points."""
    rng = np.random.default_rng(11)
    for name, functions, x, size in manifold_cases(rng):
        zero = np.zeros(size)
        at_x = functions(x, x, zero)
        np.testing.assert_allclose(at_x.plus, x, atol=1e-15, err_msg=f"{name}: Plus(x, 0) = x")
        np.testing.assert_allclose(at_x.minus, zero, atol=1e-15, err_msg=f"{name}: Minus(x, x) = 0")
        for _ in range(20):
            delta = 0.3 * rng.normal(size=size)
            y = functions(x, x, delta).plus
            back = functions(x, y, zero).minus
            np.testing.assert_allclose(back, delta, atol=1e-12, err_msg=f"{name}: Minus(Plus(x, d), x) = d")
            again = functions(x, x, back).plus
            np.testing.assert_allclose(again, y, atol=1e-12, err_msg=f"{name}: Plus(x, Minus(y, x)) = y")
        plus_numeric = numeric_jacobian(lambda d: functions(x, x, d).plus, zero)
        assert relative_error(at_x.plus_jacobian, plus_numeric) < TOLERANCE, name
        minus_numeric = numeric_jacobian(lambda y: functions(x, y, zero).minus, x)
        # Minus is defined on the manifold only: compare along its tangent directions.
        P = at_x.plus_jacobian
        assert relative_error(at_x.minus_jacobian @ P, minus_numeric @ P) < TOLERANCE, name
        np.testing.assert_allclose(at_x.minus_jacobian @ P, np.eye(size), atol=1e-12,
                                   err_msg=f"{name}: MinusJacobian * PlusJacobian = I")


def test_plane_manifold_keeps_a_unit_normal_and_the_fixed_offset() -> None:
    rng = np.random.default_rng(5)
    x = np.array([0.0, 0.6, 0.8, 2.0])
    for _ in range(20):
        plus = ba.plane_manifold(x[:3], True, x, x, rng.normal(size=2)).plus
        assert abs(np.linalg.norm(plus[:3]) - 1.0) < 1e-14
        assert plus[3] == 2.0
    pose = np.array([0.1, 0.2, 0.3, 1.0, -2.0, 0.5])
    for _ in range(20):
        plus = ba.fixed_distance_pose_manifold(pose[3:], pose, pose, rng.normal(size=5)).plus
        assert abs(np.linalg.norm(plus[3:]) - np.linalg.norm(pose[3:])) < 1e-14


def reference_projector_residual(projector: np.ndarray, weight: float, surface_map: np.ndarray, lens: np.ndarray,
                                 ab: np.ndarray) -> np.ndarray:
    """weight * (G(a, b) - u~ (1 + k1 r^2 + k2 r^4)), G the homography of the map (g33 = 1)."""
    G = np.append(surface_map, 1.0).reshape(3, 3)
    h = G @ np.array([ab[0], ab[1], 1.0])
    r2 = float(projector @ projector)
    return weight * (h[:2] / h[2] - projector * (1.0 + lens[0] * r2 + lens[1] * r2 * r2))


def test_projector_cost_jacobians_match_numeric() -> None:
    rng = np.random.default_rng(7)
    for _ in range(50):
        projector = rng.uniform([-0.5, -0.28], [0.5, 0.28])
        # A ceiling projector's map of a floor: near-affine with a small perspective part.
        surface_map = np.array([0.4, 0.02, 0.01, -0.03, 0.41, -0.02, 0.0, 0.0]) + rng.normal(scale=0.02, size=8)
        lens = rng.normal(scale=0.05, size=2)
        ab = rng.uniform(-1.5, 1.5, size=2)
        weight = rng.uniform(1.0, 1e4)
        ok, residual, (J_map, J_lens, J_ab) = ba.evaluate_projector_cost(projector, weight, surface_map, lens, ab)
        assert ok
        expected = reference_projector_residual(projector, weight, surface_map, lens, ab)
        np.testing.assert_allclose(residual, expected, rtol=1e-10, atol=1e-10 * weight)
        for analytic, f, x in (
                (J_map, lambda g: reference_projector_residual(projector, weight, g, lens, ab), surface_map),
                (J_lens, lambda k: reference_projector_residual(projector, weight, surface_map, k, ab), lens),
                (J_ab, lambda v: reference_projector_residual(projector, weight, surface_map, lens, v), ab)):
            assert relative_error(analytic, numeric_jacobian(f, x)) < TOLERANCE


def test_projector_cost_refuses_a_point_on_the_maps_vanishing_line() -> None:
    surface_map = np.array([1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0])  # h3 = a + 1
    ok, _, _ = ba.evaluate_projector_cost(np.zeros(2), 1.0, surface_map, np.zeros(2), np.array([-1.0, 0.3]))
    assert not ok


def spline_weights(t: float, cubic: bool) -> np.ndarray:
    """The uniform B-spline's weights at t in [0, 1] of the nodes at -1, 0, 1, 2 (cubic)
    or the corners 0, 1 (bilinear) along one axis of a cell."""
    if not cubic:
        return np.array([1 - t, t])
    return np.array([(1 - t) ** 3, 3 * t ** 3 - 6 * t ** 2 + 4, -3 * t ** 3 + 3 * t ** 2 + 3 * t + 1, t ** 3]) / 6


def relief_height(ab: np.ndarray, nodes: np.ndarray, spacing: float) -> float:
    """The height over the cell [0, spacing]^2 of its 4 corners (bilinear, order (0, 0),
    (1, 0), (0, 1), (1, 1)) or of its 16 cubic control points (node j * 4 + i at spacing *
    (i - 1, j - 1)); outside the cell, that of the nearest point of its edge."""
    s, t = np.clip(ab / spacing, 0.0, 1.0)
    cubic = len(nodes) == 16
    return float(nodes @ np.outer(spline_weights(t, cubic), spline_weights(s, cubic)).ravel())


def reference_relief_residual(pose: np.ndarray, plane: np.ndarray, ab: np.ndarray, nodes: np.ndarray,
                              spacing: float, observed: np.ndarray) -> np.ndarray:
    """The plane's point raised along the normal by the relief's height."""
    raised = np.append(plane[:3], plane[3] + relief_height(ab, nodes, spacing))
    return reference_residual(pose, plane_point(raised, ab), observed)


def test_cubic_relief_weights_reproduce_a_quadratic_floor() -> None:
    """A cubic B-spline's control points sampled from a quadratic q (corrected by its
    second difference, q(x) - q''(x) h^2 / 6) give q itself everywhere in the cell, with
    its slope: the spline has no kinks on a curved floor, where a bilinear cell misses
    q's curvature by up to spacing^2 q'' / 8."""
    spacing = 0.2
    a2, b2, ab2 = 0.3, -0.2, 0.1  # q = a2 a^2 + b2 b^2 + ab2 a b + 0.01 a - 0.02 b + 0.003

    def q(a, b):
        return a2 * a * a + b2 * b * b + ab2 * a * b + 0.01 * a - 0.02 * b + 0.003
    grid = spacing * (np.arange(4) - 1.0)
    bb, aa = np.meshgrid(grid, grid, indexing="ij")
    nodes = (q(aa, bb) - (2 * a2 + 2 * b2) * spacing ** 2 / 6).ravel()
    rng = np.random.default_rng(5)
    for ab in rng.uniform(0.0, spacing, size=(20, 2)):
        assert relief_height(ab, nodes, spacing) == pytest.approx(q(*ab), abs=1e-15)
    corners = q(np.array([0, spacing, 0, spacing]), np.array([0, 0, spacing, spacing]))
    middle = np.array([spacing / 2, spacing / 2])
    assert abs(relief_height(middle, corners, spacing) - q(*middle)) > 1e-3 * spacing ** 2


@pytest.mark.parametrize("node_count", [4, 16])
def test_relief_cost_jacobians_match_numeric(node_count: int) -> None:
    rng = np.random.default_rng(11)
    spacing = 0.5
    for _ in range(30):
        n = rng.normal(size=3) + np.array([0.0, 0.0, 3.0])
        plane = np.append(n / np.linalg.norm(n), rng.uniform(1.0, 3.0))
        # Inside the cell and a little outside it (a point that moved during the solve).
        ab = rng.uniform(-0.1, 0.6, size=2)
        nodes = rng.normal(scale=0.01, size=node_count)
        pose = camera_looking_at(rng, plane_point(plane, ab), 0.4)
        observed = rng.uniform([0, 0], [1920, 1080])
        ok, residual, jacobians = ba.evaluate_relief_cost(K, observed, spacing, pose, plane, ab, nodes)
        assert ok
        args = [pose, plane, ab, nodes]
        np.testing.assert_allclose(residual, reference_relief_residual(*args, spacing, observed), rtol=1e-10, atol=1e-8)

        def along(block):
            return lambda x: reference_relief_residual(*[x if k == block else a for k, a in enumerate(args)],
                                                       spacing, observed)
        for block, analytic in enumerate(jacobians[:3]):
            assert relative_error(analytic, numeric_jacobian(along(block), args[block])) < TOLERANCE
        node_jacobian = np.column_stack([J.ravel() for J in jacobians[3:]])
        assert relative_error(node_jacobian, numeric_jacobian(along(3), nodes)) < TOLERANCE
        # A cost asked for some Jacobians only gives those, the same.
        want = [False] * (3 + node_count)
        want[2] = want[4] = True
        ok, _, partial = ba.evaluate_relief_cost(K, observed, spacing, pose, plane, ab, nodes, want)
        assert partial[0] is None and partial[1] is None
        np.testing.assert_allclose(partial[2], jacobians[2], rtol=1e-12)
        np.testing.assert_allclose(partial[4], jacobians[4], rtol=1e-12)


def _foot(ab, nodes, spacing, apex):
    """Where the line from the projector's centre (height e = 1 / apex[0] above plane
    coordinates C = apex[1:] / apex[0]) through a centre at ``ab`` raised by the relief's
    height meets the plane."""
    h = relief_height(ab, nodes, spacing)
    e, centre = 1.0 / apex[0], apex[1:] / apex[0]
    return centre + (ab - centre) * e / (e - h)  # similar triangles from the projector's centre


def reference_relief_projector_residual(projector, weight, surface_map, lens, ab, apex, nodes, spacing):
    """The projector term of a raised centre: the projector's map must place it at the
    foot of its ray on the plane."""
    return reference_projector_residual(projector, weight, surface_map, lens, _foot(ab, nodes, spacing, apex))


@pytest.mark.parametrize("node_count", [4, 16])
def test_relief_projector_cost_jacobians_match_numeric(node_count: int) -> None:
    rng = np.random.default_rng(13)
    spacing = 0.5
    for _ in range(30):
        projector = rng.uniform([-0.5, -0.28], [0.5, 0.28])
        surface_map = np.array([0.4, 0.02, 0.01, -0.03, 0.41, -0.02, 0.0, 0.0]) + rng.normal(scale=0.02, size=8)
        lens = rng.normal(scale=0.05, size=2)
        ab = rng.uniform(-0.1, 0.6, size=2)
        nodes = rng.normal(scale=0.01, size=node_count)
        height = rng.uniform(1.0, 3.0) * rng.choice([-1.0, 1.0])  # either side of the plane's normal
        apex = np.append(1.0, rng.uniform(-1.0, 1.0, size=2)) / height
        weight = rng.uniform(1.0, 1e4)
        args = [surface_map, lens, ab, apex, nodes]
        ok, residual, jacobians = ba.evaluate_relief_projector_cost(projector, weight, surface_map, lens, spacing, ab,
                                                                    apex, nodes)
        assert ok

        def along(block):
            return lambda x: reference_relief_projector_residual(
                projector, weight, *[x if k == block else a for k, a in enumerate(args)], spacing)
        np.testing.assert_allclose(residual, along(0)(surface_map), rtol=1e-10, atol=1e-10 * weight)
        for block in (0, 2):
            assert relative_error(jacobians[block], numeric_jacobian(along(block), args[block])) < TOLERANCE
        # The apex moves a residual of up to 1e4 x 0.5 by a few hundredths: a step of 1e-6
        # would measure the differences' rounding (1e-5 relative); the foot is smooth in
        # the apex, so a larger step costs nothing in truncation.
        assert relative_error(jacobians[3], numeric_jacobian(along(3), apex, rel_step=1e-4)) < TOLERANCE
        # The lens only moves the projector pixel: its block is the plain cost's at the foot
        # (checked against numeric above; differences of a residual of up to 1e4 x 0.5
        # would only measure their own rounding here).
        foot = _foot(ab, nodes, spacing, apex)
        _, _, (_, J_lens, _) = ba.evaluate_projector_cost(projector, weight, surface_map, lens, foot)
        np.testing.assert_allclose(jacobians[1], J_lens, rtol=1e-12, atol=1e-12 * weight)
        node_jacobian = np.column_stack([J.ravel() for J in jacobians[4:]])
        assert relative_error(node_jacobian, numeric_jacobian(along(4), nodes)) < TOLERANCE


@pytest.mark.parametrize("node_count", [4, 16])
def test_relief_projector_cost_sees_a_raised_centre_along_the_projectors_ray(node_count: int) -> None:
    """A pinhole projector 3 m above the floor at (0.4, -0.2) m and a centre 6 mm up at
    (1.1, 0.5) m: the cost is zero at the pixel of the ray's foot on the floor, not at the
    pixel straight below the centre (2 mm away)."""
    centre, height = np.array([0.4, -0.2]), 3.0
    ab, h = np.array([1.1, 0.5]), 0.006
    foot = centre + (ab - centre) * height / (height - h)
    surface_map = np.array([0.25, 0.0, 0.0, 0.0, 0.25, 0.0, 0.0, 0.0])  # u = 0.25 * (a, b)
    apex = np.append(1.0, centre) / height
    nodes = np.full(node_count, h)  # a level relief, whichever its shape
    _, residual, _ = ba.evaluate_relief_projector_cost(0.25 * foot, 1.0, surface_map, np.zeros(2), 5.0, ab, apex, nodes)
    np.testing.assert_allclose(residual, 0.0, atol=1e-15)
    _, below, _ = ba.evaluate_relief_projector_cost(0.25 * ab, 1.0, surface_map, np.zeros(2), 5.0, ab, apex, nodes)
    assert np.linalg.norm(below) == pytest.approx(0.25 * np.linalg.norm(foot - ab), rel=1e-9)
