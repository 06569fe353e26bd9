"""Bundle-adjustment speed on the paper's synthetic rig: analytic Ceres vs Ceres AutoDiff vs scipy.

The same rig (10 cameras, 3200 floor points, 0.5 px noise) and the same perturbed start
(2 deg, 5 cm on every pose, 5 cm on every point) are solved by
  (a) calibproj's analytic-Jacobian Ceres bundle adjuster,
  (b) the same problem layout with Ceres AutoDiff costs (benchmark-only module),
  (c) scipy.optimize.least_squares(method='trf', x_scale='jac', jac_sparsity=...),
in interleaved runs; medians are reported. The last two lines are

  ba_speed free: analytic_vs_autodiff=X analytic_vs_scipy=Y cost_rel_diff=Z
  ba_speed coplanar: analytic_vs_autodiff=X analytic_vs_scipy=Y cost_rel_diff=Z

with speed ratios = time of the other / time of ours, and cost_rel_diff the largest
relative difference of the final costs from ours. Then the cost of the poses' joint
covariance (the reduced camera system, cross terms included) in a calibration of the
paper rig and of the or-full room from their simulated tracks: its time over the time
of the final bundle adjustment (the refinement: relief test, rounds of adjustment,
noise estimate and outlier filter), each covariance of every round counted:

  ba_speed covariance: paper_share=X or_full_share=Y
"""

from __future__ import annotations

import argparse
import logging
import statistics
import time

import numpy as np

from calibproj import _bench, _core
from calibproj.simulate.synthetic import paper_ring_rig, perturb_poses


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=5, help="interleaved runs per method (default 5)")
    parser.add_argument("--seed", type=int, default=0, help="rig and perturbation seed (default 0)")
    parser.add_argument("--noise", type=float, default=0.5, help="observation noise in px (default 0.5)")
    parser.add_argument("--threads", type=int, default=1, help="Ceres threads (default 1; scipy is single-threaded)")
    parser.add_argument("--models", default="free,coplanar", help="comma-separated models (default free,coplanar)")
    parser.add_argument("--no-scipy", action="store_true", help="skip the scipy baseline")
    parser.add_argument("--report", action="store_true", help="print Ceres's full report of one analytic run")
    parser.add_argument("--covariance-scenes", default="paper,or-full",
                        help="scenes whose calibration times the covariance (default paper,or-full; empty: none)")
    return parser.parse_args()


def rodrigues(w: np.ndarray) -> np.ndarray:
    """Rotation matrices (C, 3, 3) of angle-axis vectors (C, 3)."""
    theta = np.linalg.norm(w, axis=1)[:, None, None]
    safe = np.where(theta > 1e-12, theta, 1.0)
    k = w[:, :, None] / safe
    kx = np.zeros((len(w), 3, 3))
    kx[:, 0, 1], kx[:, 0, 2], kx[:, 1, 2] = -k[:, 2, 0], k[:, 1, 0], -k[:, 0, 0]
    kx -= kx.transpose(0, 2, 1)
    return np.eye(3) + np.sin(theta) * kx + (1.0 - np.cos(theta)) * kx @ kx


def householder_points(plane: np.ndarray, ab: np.ndarray) -> np.ndarray:
    n, d = plane[:3], plane[3]
    v = n + np.array([0.0, 0.0, 1.0])
    basis = (np.eye(3) - np.outer(v, v) / (1.0 + n[2]))[:, :2]
    return d * n + ab @ basis.T


class ScipyProblem:
    """The same residuals as calibproj's bundle adjuster, for scipy.optimize.least_squares.

    Camera 0 is held fixed; the remaining similarity gauge (scale) is left to the
    trust region, as the paper's reference code does.
    """

    def __init__(self, problem, model: str, poses: np.ndarray, points: np.ndarray, plane: np.ndarray):
        self.problem, self.model = problem, model
        self.fixed_pose = poses[0]
        self.num_cameras, self.num_points = len(poses), len(points)
        self.K = problem.K[problem.camera_index]
        n = plane[:3] / np.linalg.norm(plane[:3])
        self.plane0 = np.concatenate([n, [plane[3] / np.linalg.norm(plane[:3])]])
        v = n + np.array([0.0, 0.0, 1.0])
        self.basis0 = (np.eye(3) - np.outer(v, v) / (1.0 + n[2]))[:, :2]
        if model == "free":
            point_params = points
        else:
            point_params = (points - self.plane0[3] * n) @ self.basis0
        plane_params = np.zeros(3) if model == "coplanar" else np.zeros(0)
        self.x0 = np.concatenate([poses[1:].ravel(), plane_params, point_params.ravel()])

    def unpack(self, x: np.ndarray):
        c = 6 * (self.num_cameras - 1)
        poses = np.vstack([self.fixed_pose, x[:c].reshape(-1, 6)])
        if self.model == "free":
            return poses, x[c:].reshape(-1, 3)
        n = self.plane0[:3] + self.basis0 @ x[c : c + 2]
        n /= np.linalg.norm(n)
        plane = np.concatenate([n, [self.plane0[3] + x[c + 2]]])
        return poses, householder_points(plane, x[c + 3 :].reshape(-1, 2))

    def residuals(self, x: np.ndarray) -> np.ndarray:
        poses, points = self.unpack(x)
        p = self.problem
        R = rodrigues(poses[:, :3])[p.camera_index]
        cam = np.einsum("nij,nj->ni", R, points[p.point_index]) + poses[p.camera_index, 3:]
        uv = np.einsum("nij,nj->ni", self.K, cam / cam[:, 2:3])
        return (uv[:, :2] - p.observed).ravel()

    def sparsity(self):
        from scipy.sparse import lil_matrix

        p = self.problem
        point_size = 3 if self.model == "free" else 2
        plane_size = 3 if self.model == "coplanar" else 0
        first_point = 6 * (self.num_cameras - 1) + plane_size
        A = lil_matrix((2 * len(p.camera_index), len(self.x0)), dtype=int)
        rows = np.arange(len(p.camera_index))
        for r in (2 * rows, 2 * rows + 1):
            for k in range(6):
                moving = p.camera_index > 0
                A[r[moving], 6 * (p.camera_index[moving] - 1) + k] = 1
            for k in range(plane_size):
                A[r, 6 * (self.num_cameras - 1) + k] = 1
            for k in range(point_size):
                A[r, first_point + point_size * p.point_index + k] = 1
        return A


def run_scipy(problem, model, poses, points, plane, sparsity_cache):
    from scipy.optimize import least_squares

    scipy_problem = ScipyProblem(problem, model, poses, points, plane)
    if model not in sparsity_cache:
        sparsity_cache[model] = scipy_problem.sparsity()
    start = time.perf_counter()
    result = least_squares(
        scipy_problem.residuals,
        scipy_problem.x0,
        method="trf",
        x_scale="jac",
        jac_sparsity=sparsity_cache[model],
        ftol=1e-12,
        xtol=1e-12,
        gtol=1e-12,
    )
    elapsed = time.perf_counter() - start
    return elapsed, float(result.cost), int(result.nfev)


def run_ceres(solver, problem, model, poses, points, plane, threads):
    start = time.perf_counter()
    result = solver(
        problem.camera_index, problem.point_index, problem.observed, problem.K, poses, points, plane,
        model=model, num_threads=threads,
    )
    elapsed = time.perf_counter() - start
    return elapsed, float(result.final_cost), int(result.iterations)


def ceres_time_breakdown(solver, problem, model, poses, points, plane, threads) -> str:
    result = solver(
        problem.camera_index, problem.point_index, problem.observed, problem.K, poses, points, plane,
        model=model, num_threads=threads, full_report=True,
    )
    keep = ("Schur structure", "Linear solver  ", "Residual only", "Jacobian & residual", "Linear solver ", "Minimizer  ", "Total")
    lines = [line.strip() for line in result.report.splitlines() if line.strip().startswith(tuple(k.strip() for k in keep))]
    return "\n    ".join(lines)


def main() -> None:
    args = parse_args()
    logging.basicConfig(level=logging.ERROR)  # the registration's warnings are not this bench's
    problem = paper_ring_rig(seed=args.seed, noise_px=args.noise)
    rng = np.random.default_rng(args.seed + 1)
    poses = perturb_poses(problem.poses, rotation_deg=2.0, translation_m=0.05, rng=rng)
    points = problem.points + rng.normal(0.0, 0.05, problem.points.shape)
    plane = np.array([0.02, -0.03, 1.0, 0.04])
    print(
        f"rig: {len(problem.poses)} cameras, {len(problem.points)} points, {len(problem.observed)} observations, "
        f"noise {args.noise} px, {args.runs} interleaved runs, {args.threads} Ceres thread(s)"
    )
    methods = {
        "analytic": lambda m: run_ceres(_core.ba.bundle_adjust, problem, m, poses, points, plane, args.threads),
        "autodiff": lambda m: run_ceres(_bench.bundle_adjust_autodiff, problem, m, poses, points, plane, args.threads),
    }
    sparsity_cache: dict = {}
    if not args.no_scipy:
        methods["scipy"] = lambda m: run_scipy(problem, m, poses, points, plane, sparsity_cache)

    summary_lines = []
    print(f"\n{'model':<9} {'method':<9} {'median s':>10} {'min s':>9} {'final cost':>16} {'iters/nfev':>10}")
    for model in args.models.split(","):
        times = {name: [] for name in methods}
        costs, iterations = {}, {}
        for _ in range(args.runs):
            for name, run in methods.items():
                elapsed, cost, its = run(model)
                times[name].append(elapsed)
                costs[name], iterations[name] = cost, its
        for name in methods:
            print(
                f"{model:<9} {name:<9} {statistics.median(times[name]):>10.4f} {min(times[name]):>9.4f} "
                f"{costs[name]:>16.6f} {iterations[name]:>10d}"
            )
        ours = statistics.median(times["analytic"])
        autodiff_ratio = statistics.median(times["autodiff"]) / ours
        scipy_ratio = statistics.median(times["scipy"]) / ours if "scipy" in times else float("nan")
        cost_rel = max(abs(costs[name] - costs["analytic"]) / costs["analytic"] for name in methods)
        for name in ("analytic", "autodiff"):
            solver = _core.ba.bundle_adjust if name == "analytic" else _bench.bundle_adjust_autodiff
            print(f"  Ceres time breakdown, {model} {name}:\n    "
                  + ceres_time_breakdown(solver, problem, model, poses, points, plane, args.threads))
        summary_lines.append(
            f"ba_speed {model}: analytic_vs_autodiff={autodiff_ratio:.2f} "
            f"analytic_vs_scipy={scipy_ratio:.1f} cost_rel_diff={cost_rel:.2e}"
        )
    if args.report:
        print(_core.ba.bundle_adjust(problem.camera_index, problem.point_index, problem.observed, problem.K,
                                     poses, points, plane, full_report=True)["report"])
    scenes = [scene for scene in args.covariance_scenes.split(",") if scene]
    shares = {scene: covariance_share(scene, args.seed, args.runs) for scene in scenes}
    if shares:
        summary_lines.append("ba_speed covariance: " + " ".join(
            f"{scene.replace('-', '_')}_share={share:.3f}" for scene, share in shares.items()))
    print()
    for line in summary_lines:
        print(line)


def covariance_share(scene: str, seed: int, runs: int) -> float:
    """Median over runs of the covariance's time over the refinement's, in a calibration
    of the scene's simulated tracks (the registration driven as calibrate drives it)."""
    from calibproj.registration.driver import RegistrationDriver
    from calibproj.simulate import simulate_tracks

    sim = simulate_tracks(scene, None, noise_px=0.3, seed=seed)
    shares, refine_times, covariance_times = [], [], []
    for _ in range(runs):
        driver = RegistrationDriver(sim.tracks, sim.intrinsics)
        refined = next(step.result for step in driver.steps() if step.name == "refine")
        shares.append(refined.covariance_seconds / refined.seconds)
        refine_times.append(refined.seconds)
        covariance_times.append(refined.covariance_seconds)
    print(f"covariance, {scene}: final bundle adjustment median {statistics.median(refine_times):.3f} s, "
          f"its covariances {statistics.median(covariance_times):.4f} s ({statistics.median(shares):.1%})")
    return statistics.median(shares)


if __name__ == "__main__":
    main()
