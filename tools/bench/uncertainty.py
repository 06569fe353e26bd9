"""Monte Carlo of the predicted uncertainty: does uncertainty.json tell the truth?

Per scene, a room's MSM tracks are simulated without noise and calibrated once with
noise (the nominal calibration, whose covariance makes the prediction). Then the same
observations get fresh noise of the same size --runs times and are calibrated again
from scratch (the whole registration, coplanar model: noise estimate, outliers, final
bundle adjustment), each calibration brought into the nominal one's gauge (the
reference camera's pose and its height above the floor, which the covariance holds). Over the
runs it measures:

- per camera, how far the points of the working volume it sees project from run to
  run (px), against the predicted projection uncertainty (uncertainty.json's cameras);
- per cell of the volume map seen by two cameras or more, the spread of the cell's
  centre triangulated, in each run, from fresh pixels with that run's calibration
  (weighted as the prediction weighs the cameras), against the predicted error.

A figure is "within 25 %" when the empirical 1 sigma (root of the trace of the
covariance) is within 25 % of the predicted one. The calibrations take
error_correlation 0 and shared_error_shift 0: the fresh noise is white, which is what
the prediction then assumes (the defaults widen the covariance for errors shared within
a camera, which white noise does not have; their factor is printed). The last line:

    uncertainty: cells_within_25pct=.. projection_within_25pct=..

    python tools/bench/uncertainty.py --scenes or-full,demo --runs 50

With --refine-intrinsics, the intrinsics given are --focal-error off (the simulated
distortion kept) and every calibration refines them: the prediction then carries the
refined lenses' uncertainty, and each run's new pixels are undistorted with that run's
own lenses (a point is triangulated from raw pixels; a projection is compared in the
nominal calibration's undistorted pixels):

    python tools/bench/uncertainty.py --scenes demo,or-full --runs 50 --refine-intrinsics focal,k1
"""

from __future__ import annotations

import argparse
import logging
import tempfile
import time
from pathlib import Path

import numpy as np

from calibproj import _core
from calibproj.formats.intrinsics import Intrinsics, load_intrinsics_dir
from calibproj.pipeline import calibrate
from calibproj.registration.driver import RegistrationOptions
from calibproj.selfcal.lenses import convert_tracks
from calibproj.simulate import simulate_tracks
from calibproj.formats.tracks import Tracks


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", default="or-full,demo", help="scene presets (default or-full,demo)")
    parser.add_argument("--runs", type=int, default=50, help="re-noised calibrations per scene (default 50)")
    parser.add_argument("--noise", type=float, default=0.3, help="centre noise in px (default 0.3)")
    parser.add_argument("--seed", type=int, default=0, help="scene and noise seed (default 0)")
    parser.add_argument("--refine-intrinsics", default=None,
                        help="lens entries every calibration refines (e.g. focal,k1); default: none")
    parser.add_argument("--focal-error", type=float, default=0.05,
                        help="with --refine-intrinsics: the given focal lengths' error, a share (default 0.05)")
    return parser.parse_args()


def focal_off(intrinsics: Intrinsics, share: float) -> Intrinsics:
    K = intrinsics.K.copy()
    K[:2, :2] *= 1.0 + share
    return Intrinsics(intrinsics.name, intrinsics.resolution, K, intrinsics.dist.copy())


class Calibrator:
    """Calibrates re-noised tracks, with the given intrinsics or refining them; returns
    the calibration and the intrinsics it ends with."""

    def __init__(self, clean, args: argparse.Namespace, folder: Path) -> None:
        self.refine = args.refine_intrinsics
        self.given = dict(clean.intrinsics)
        self.tracks = clean.tracks
        if self.refine:
            self.given = {name: focal_off(i, args.focal_error) for name, i in clean.intrinsics.items()}
            self.tracks = convert_tracks(clean.tracks, clean.intrinsics, self.given)
        self.folder = folder

    def __call__(self, noise_px: float, rng: np.random.Generator, **kwargs):
        tracks = renoised(self.tracks, noise_px, rng)
        if not self.refine:
            return calibrate(tracks, self.given, progress=False, **kwargs), self.given
        out = self.folder / "run"
        calibration = calibrate(tracks, self.given, progress=False, refine_intrinsics=[self.refine], out=out,
                                force=True, report=False, **kwargs)
        return calibration, load_intrinsics_dir(out / "intrinsics")


def renoised(tracks: Tracks, noise_px: float, rng: np.random.Generator) -> Tracks:
    camera_index, point_index, xy = tracks.bundle_arrays()
    return Tracks.from_observations(tracks.camera_names, camera_index, tracks.point_ids[point_index],
                                    xy + rng.normal(0.0, noise_px, xy.shape))


def into_gauge(poses: dict, nominal: dict, reference: str) -> dict:
    """The run's poses in the nominal calibration's gauge: the reference camera's pose and
    its height above the floor made the nominal ones (a similarity of the world)."""
    R_run, t_run = poses[reference]
    R_nom, t_nom = nominal[reference]
    scale = (-R_nom.T @ t_nom)[2] / (-R_run.T @ t_run)[2]
    rotation = R_nom.T @ R_run  # world_nominal = scale * rotation @ world_run + shift
    shift = -R_nom.T @ t_nom - scale * rotation @ (-R_run.T @ t_run)
    out = {}
    for name, (R, t) in poses.items():
        R_new = R @ rotation.T
        out[name] = (R_new, scale * t - R_new @ shift)
    return out


def project(K: np.ndarray, R: np.ndarray, t: np.ndarray, X: np.ndarray) -> np.ndarray:
    x = X @ R.T + t
    return (x[:, :2] / x[:, 2:]) * np.diag(K)[:2] + K[:2, 2]


def triangulate(cameras: list, pixels: list, weights: list, masks: list, start: np.ndarray) -> np.ndarray:
    """Weighted Gauss-Newton per point (N, 3) over the cameras that see it."""
    X = start.copy()
    for _ in range(4):
        H = np.zeros((len(X), 3, 3))
        g = np.zeros((len(X), 3))
        for (K, R, t), u, W, mask in zip(cameras, pixels, weights, masks):
            x = X[mask] @ R.T + t
            z = x[:, 2]
            d = np.zeros((mask.sum(), 2, 3))
            d[:, 0, 0] = K[0, 0] / z
            d[:, 0, 2] = -K[0, 0] * x[:, 0] / z**2
            d[:, 1, 1] = K[1, 1] / z
            d[:, 1, 2] = -K[1, 1] * x[:, 1] / z**2
            J = d @ R
            r = project(K, R, t, X[mask]) - u
            JtW = np.transpose(J, (0, 2, 1)) @ W
            H[mask] += JtW @ J
            g[mask] += (JtW @ r[:, :, None])[:, :, 0]
        X = X - np.linalg.solve(H, g[:, :, None])[:, :, 0]
    return X


def sigma_of(covariances: np.ndarray) -> np.ndarray:
    return np.sqrt(np.trace(covariances, axis1=-2, axis2=-1))


def study(scene: str, args: argparse.Namespace) -> tuple[float, float]:
    clean = simulate_tracks(scene, None, noise_px=0.0, seed=args.seed)
    with tempfile.TemporaryDirectory() as folder:
        return study_with(scene, clean, Calibrator(clean, args, Path(folder)), args)


def study_with(scene: str, clean, calibrator: Calibrator, args: argparse.Namespace) -> tuple[float, float]:
    rng = np.random.default_rng(args.seed)
    options = RegistrationOptions(error_correlation=0.0, shared_error_shift=0.0, shared_error_field=0.0)
    start = time.perf_counter()
    nominal, intrinsics = calibrator(args.noise, rng, options=options)
    default, _ = calibrator(args.noise, np.random.default_rng(args.seed))
    one = time.perf_counter() - start
    u = nominal.uncertainty
    reference, names = u.reference, list(u.cameras)
    intrinsics = {name: intrinsics[name] for name in names}
    cells = volume_cells(nominal, intrinsics)
    predicted, _, seen = _core.uncertainty.triangulation(nominal, intrinsics, cells, 0.0)
    usable = np.isfinite(predicted).all(axis=(1, 2))
    cells, predicted, seen = cells[usable], predicted[usable], [s for s, ok in zip(seen, usable) if ok]
    inflation = np.median(sigma_of(_core.uncertainty.triangulation(default, intrinsics, cells, 0.0)[0])
                          / sigma_of(predicted))
    lenses = [name for name, block in zip(names, u.lens_block) if block >= 0]
    print(f"\n{scene}: {len(names)} cameras, reference {reference}, {len(cells)} cells seen by 2+, "
          f"noise {args.noise} px, {args.runs} runs (~{one / 2:.1f} s each); "
          f"lenses in the prediction: {', '.join(lenses) or 'none'}")
    print(f"  the default shared errors widen the predicted error by {inflation:.2f}x (median)")
    masks = [np.array([name in s for s in seen]) for name in names]
    projections = {name: _core.uncertainty.projection(nominal, intrinsics, name, cells) for name in names}
    weights = [np.linalg.inv(u.noise_px[c] ** 2 * np.eye(2) + projections[name][masks[c]])
               for c, name in enumerate(names)]
    Ks = [np.asarray(intrinsics[name].K, dtype=float) for name in names]
    truth = [project(Ks[c], *nominal.poses[name], cells[masks[c]]) for c, name in enumerate(names)]
    placed, projected = [], {name: [] for name in names}
    for run in range(args.runs):
        calibration, lenses_of_run = calibrator(args.noise, rng, options=options)
        if sorted(calibration.poses) != sorted(nominal.poses):
            print(f"  run {run}: cameras {sorted(calibration.poses)} registered; left out")
            continue
        poses = into_gauge(calibration.poses, nominal.poses, reference)
        run_Ks = [np.asarray(lenses_of_run[name].K, dtype=float) for name in names]
        cameras = [(run_Ks[c], *poses[name]) for c, name in enumerate(names)]
        # Raw pixels of the nominal calibration's points, undistorted with the run's lenses.
        pixels = [lenses_of_run[name].undistort_points(intrinsics[name].distort_points(
            truth[c] + rng.normal(0.0, u.noise_px[c], truth[c].shape))) for c, name in enumerate(names)]
        placed.append(triangulate(cameras, pixels, weights, masks, cells))
        for c, name in enumerate(names):
            projected[name].append(lenses_of_run[name].distort_points(project(run_Ks[c], *poses[name], cells[masks[c]])))
    placed = np.array(placed)
    deviations = placed - placed.mean(axis=0)
    empirical = np.einsum("rni,rnj->nij", deviations, deviations) / (len(placed) - 1)
    ratio = sigma_of(empirical) / sigma_of(predicted)
    cells_ok = float(np.mean(np.abs(ratio - 1.0) <= 0.25))
    print(f"  triangulation: empirical / predicted 1 sigma per cell: median {np.median(ratio):.3f}, "
          f"p5 {np.percentile(ratio, 5):.3f}, p95 {np.percentile(ratio, 95):.3f}; "
          f"within 25 %: {cells_ok:.1%}; predicted median {np.median(sigma_of(predicted)):.4g} {nominal.unit}")
    within = []
    for c, name in enumerate(names):
        if name == reference:
            continue
        shots = np.array(projected[name])
        spread = np.mean(np.sum(np.var(shots, axis=0, ddof=1), axis=-1))
        raw = raw_covariances(intrinsics[name], truth[c], projections[name][masks[c]])
        expected = np.mean(np.trace(raw, axis1=1, axis2=2))
        r = float(np.sqrt(spread / expected))
        within.append(abs(r - 1.0) <= 0.25)
        per_cell = np.sqrt(np.sum(np.var(shots, axis=0, ddof=1), axis=-1)
                           / np.trace(raw, axis1=1, axis2=2))
        print(f"  projection {name:<10} predicted {np.sqrt(expected):8.4f} px  empirical {np.sqrt(spread):8.4f} px  "
              f"ratio {r:.3f} (per cell: median {np.median(per_cell):.3f}, max {per_cell.max():.3f})")
    return cells_ok, float(np.mean(within))


def raw_covariances(lens: Intrinsics, undistorted: np.ndarray, covariances: np.ndarray) -> np.ndarray:
    """Covariances of undistorted pixels as the raw (distorted) pixels' they make:
    T C T^T, with T the lens's derivative there (central differences). The spread is
    compared in raw pixels, where a point lands in the image."""
    step = 1e-3
    T = np.stack([(lens.distort_points(undistorted + e) - lens.distort_points(undistorted - e)) / (2 * step)
                  for e in np.eye(2) * step], axis=-1)
    return T @ covariances @ np.transpose(T, (0, 2, 1))


def volume_cells(calibration, intrinsics) -> np.ndarray:
    """The centres of uncertainty.json's map (the volume the report maps)."""
    import json

    with tempfile.TemporaryDirectory() as folder:
        _core.uncertainty.write(Path(folder), calibration, intrinsics)
        grid = json.loads((Path(folder) / _core.uncertainty.FILE).read_text())["map"]
    z, y, x = np.meshgrid(grid["z"], grid["y"], grid["x"], indexing="ij")
    return np.column_stack([x.ravel(), y.ravel(), z.ravel()])


def main() -> None:
    args = parse_args()
    logging.basicConfig(level=logging.ERROR)
    results = [study(scene, args) for scene in args.scenes.split(",")]
    cells = min(r[0] for r in results)
    projection = min(r[1] for r in results)
    print(f"\nuncertainty: cells_within_25pct={cells:.3f} projection_within_25pct={projection:.3f}")


if __name__ == "__main__":
    main()
