"""Self-calibration (``calibrate --refine-intrinsics``) against the truth of simulated rooms.

Per preset and seed, tracks are simulated with ground truth and calibrated four times:
with the true intrinsics (the reference), with nominal intrinsics (the true ones with
the focal length --focal-error too long, same principal point, no distortion) as they
are, with the nominal ones refined (--entries), and with the true lens but the refined
run's focal lengths (focal-only: how much of the refined run's pose error its focal
lengths alone make). The nominal runs see the tracks undistorted with the nominal
intrinsics, as a user who has only those would.

Per camera of the refined run it prints how far its floor observations reach towards
the image corners (coverage, from self_calibration.json), the focal error against the
truth (%), the focal's reported 1 sigma (%) and the error in units of it, and the lens
error modulo a homography over the pixels where the camera saw the floor (p99 and max,
px: a pinhole difference, i.e. focal, principal point or rotation, is a homography, so
what remains is the distortion's error), its rotation error against the truth in the
true and the refined calibrations after alignment on the camera centres (deg), and the
entries held with the reason.

Per run (true, nominal, refined, focal-only):

- pairwise rotation error, gauge-free: the RMS over every pair of cameras not reported
  weak in the true-intrinsics run and declared observable by the refinement of the
  angle between the estimated relative rotation R_i R_j^T and the true one (deg), and
  the ratio refined / true;
- rotation RMSE after Sim(3) alignment on the camera centres (``calibproj.evaluation.comparison``),
  over the cameras not weak and over all, and the ratio refined / true. The alignment
  carries the centres' error into every rotation (a focal error of 0.05 % moves the
  centres by about as much and tilts every camera by ~0.02 deg), so this mixes the
  positions' accuracy into the rotations;
- the evaluation's success at 0.5 px on the simulation's independent points (converted
  to each run's intrinsics; a camera reported weak, such as one whose focal length was
  held, does not place the points the others are judged on), over all of them, and
  restricted to where each camera saw the floor: the observations whose raw pixel lies
  inside the convex hull of the camera's raw MSM observations in the run's tracks.json
  (a lens refined from a central patch of the image holds only there).

The issue's criteria: every camera whose focal is refined (declared observable) has
|focal error| <= 0.3 % and distortion p99 <= 0.1 px; the refined pairwise rotation error
of those cameras is at most 1.5 x the true one; the evaluation on every point succeeds
for each of them. The restricted evaluation is shown beside it (over the cameras for
which it succeeds with the true intrinsics; the others are listed). The last line:
``self-calibration: worst_focal_pct=.. worst_dist_px=.. worst_pair_rot_ratio=..
worst_centre_rot_ratio=.. eval_success_observable=.. eval_success_seen=.. eval_success_all=..
rms_pair_rot_ratio=.. focal_only_rms_pair_rot_ratio=.. focal_z_rms=..``: the last three
over all rows (RMS pairwise error of the refined and the focal-only runs over the true
run's, and the RMS of the refined focal errors in units of their reported sigma).

    python tools/bench/self_calibration.py                        # or-full and demo, 1 seed
    python tools/bench/self_calibration.py --presets or-full,demo --seeds 3
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import tempfile
import time
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from calibproj.formats.calibration import Calibration
from calibproj.evaluation.comparison import compare, rotation_angle_deg
from calibproj.evaluation.independent import Evaluation, EvaluationOptions, evaluate
from calibproj.formats.intrinsics import Intrinsics, load_intrinsics_dir
from calibproj.formats.poses import read_poses
from calibproj.pipeline import calibrate
from calibproj.selfcal.lenses import FILE_NAME as SELF_CALIBRATION_FILE
from calibproj.selfcal.lenses import convert_tracks
from calibproj.simulate.geometric import GeometricSimulation, simulate_tracks
from calibproj.simulate.scene import Scene, load_scene
from calibproj.formats.tracks import Tracks

RUNS = ("true", "nominal", "refined", "focal-only")
MAX_FOCAL_PCT = 0.3
MAX_DIST_PX = 0.1
MAX_ROT_RATIO = 1.5
SUCCESS_PX = 0.5


def nominal_intrinsics(truth: Intrinsics, focal_error: float) -> Intrinsics:
    """The true K with fx, fy scaled by 1 + focal_error, no distortion."""
    K = truth.K.copy()
    K[0, 0] *= 1.0 + focal_error
    K[1, 1] *= 1.0 + focal_error
    return Intrinsics(truth.name, truth.resolution, K, np.zeros(5))


def with_focal_lengths(truth: Mapping[str, Intrinsics], refined: Mapping[str, Intrinsics]) -> dict[str, Intrinsics]:
    """The true intrinsics with fx, fy scaled as the refined focal length is."""
    out = {}
    for name, lens in truth.items():
        K = lens.K.copy()
        if name in refined:
            K[:2, :2] *= refined[name].K[0, 0] / lens.K[0, 0]
        out[name] = Intrinsics(name, lens.resolution, K, lens.dist.copy())
    return out


def true_scene(preset: str, seed: int, lens: str) -> Scene:
    """The preset's scene; with ``lens`` "k1" every camera keeps only the k1 of its lens
    (the issue's truth: a GoPro-like k1), with "full" its whole lens (k1, k2, k3 and
    the small tangential terms)."""
    scene = load_scene(preset, seed=seed)
    if lens == "full":
        return scene
    return replace(scene, cameras=tuple(replace(camera, dist=(camera.dist[0],) + (0.0,) * (len(camera.dist) - 1))
                                        for camera in scene.cameras))


def run(preset: str, seed: int, work: Path, args) -> dict:
    room = work / f"{preset}-{seed}"
    simulation = simulate_tracks(true_scene(preset, seed, args.true_lens), room, seed=seed, noise_px=args.noise_px)
    truth = simulation.intrinsics
    nominal = {name: nominal_intrinsics(lens, args.focal_error) for name, lens in truth.items()}
    converted = convert_tracks(simulation.tracks, truth, nominal)
    inputs = {"true": (simulation.tracks, truth, None), "nominal": (converted, nominal, None),
              "refined": (converted, nominal, args.entries)}
    row = {"preset": preset, "seed": seed, "runs": {}}
    for label, (tracks, intrinsics, entries) in inputs.items():
        results = room / label
        calibration = calibrate(tracks, intrinsics, out=results, report=False, force=True, progress=False,
                                refine_intrinsics=entries)
        row["runs"][label] = score(calibration, results, room, simulation)
    focal_only = with_focal_lengths(truth, load_intrinsics_dir(room / "refined" / "intrinsics"))
    results = room / "focal-only"
    calibration = calibrate(convert_tracks(simulation.tracks, truth, focal_only), focal_only, out=results,
                            report=False, force=True, progress=False)
    row["runs"]["focal-only"] = score(calibration, results, room, simulation)
    row["cameras"] = lens_errors(room / "refined", truth)
    # The pairs: cameras registered and not weak in the reference (true-intrinsics) run
    # whose focal length the refinement declared observable (a camera held keeps the
    # focal length it was given, wrong by --focal-error, and is reported as such).
    reference = row["runs"]["true"]
    row["pair_cameras"] = [name for name in reference["rot_deg"]
                           if name not in reference["weak"] and row["cameras"].get(name, {}).get("observable")]
    for label in RUNS:
        row["runs"][label]["rot_pairs"] = pair_rotation_rms(room / label / "camera_poses.json",
                                                            room / "truth.json", row["pair_cameras"])
    return row


def score(calibration: Calibration, results: Path, room: Path, simulation: GeometricSimulation) -> dict:
    """Rotation RMSE after alignment on the centres (not weak, all) and the evaluation's
    success at 0.5 px, over all evaluation points and where each camera saw the floor."""
    comparison = compare(results / "camera_poses.json", room / "truth.json")
    weak = sorted(name for name, metrics in calibration.metrics.items() if metrics.weak)
    strong = [error.rotation_deg for name, error in comparison.cameras.items() if name not in weak]
    used = load_intrinsics_dir(results / "intrinsics")
    seen = seen_floor(simulation.eval_tracks, simulation.intrinsics, Tracks.read(results / "tracks.json"), used)
    full = evaluate_with(results, simulation.eval_tracks, simulation.intrinsics, used)
    restricted = evaluate_with(results, simulation.eval_tracks.select(seen), simulation.intrinsics, used)
    return {"rot_strong": rms(strong), "rot_all": comparison.rotation_rmse_deg, "weak": weak,
            "rot_deg": {name: error.rotation_deg for name, error in comparison.cameras.items()},
            "registered": len(calibration.poses), "success": full.success_rate(SUCCESS_PX) / 100.0,
            "eval_px": camera_means(full), "success_seen": restricted.success_rate(SUCCESS_PX) / 100.0,
            "eval_seen_px": camera_means(restricted), "eval_seen_n": int(seen.sum()),
            "eval_n": len(simulation.eval_tracks)}


def evaluate_with(results: Path, eval_tracks: Tracks, truth: Mapping[str, Intrinsics],
                  used: Mapping[str, Intrinsics]) -> Evaluation:
    """The evaluation of a run on tracks undistorted with the true intrinsics, converted
    to the run's. The intrinsics folder is named so that evaluate does not convert them
    a second time."""
    return evaluate(results, convert_tracks(eval_tracks, truth, used), results / "intrinsics",
                    options=EvaluationOptions(weak_cameras_place_points=False))


def camera_means(evaluation: Evaluation) -> dict[str, float | None]:
    """Per camera, its mean evaluation error (px; None when it has none)."""
    return {name: camera.mean_px for name, camera in evaluation.cameras.items()}


def succeeded(mean_px: float | None) -> bool:
    return mean_px is not None and mean_px < SUCCESS_PX


def seen_floor(eval_tracks: Tracks, truth: Mapping[str, Intrinsics], floor: Tracks,
               used: Mapping[str, Intrinsics]) -> np.ndarray:
    """Mask of the evaluation observations (undistorted with ``truth``) whose raw pixel
    lies inside the convex hull of the same camera's raw MSM observations (``floor``,
    undistorted with ``used``)."""
    keep = np.zeros(len(eval_tracks), dtype=bool)
    for c, name in enumerate(eval_tracks.camera_names):
        if name not in floor.camera_names or name not in used:
            continue
        _, xy = floor.observations(name)
        if len(xy) < 3:
            continue
        hull = cv2.convexHull(used[name].distort_points(xy).astype(np.float32))
        rows = np.flatnonzero(eval_tracks.camera_index == c)
        pixels = truth[name].distort_points(eval_tracks.xy[rows])
        keep[rows] = [cv2.pointPolygonTest(hull, (float(x), float(y)), False) >= 0 for x, y in pixels]
    return keep


def pair_rotation_rms(estimate: Path, truth: Path, names: list[str]) -> float:
    """RMS over the pairs of ``names`` (both registered in ``estimate``) of the angle
    between the estimated relative rotation R_i R_j^T and the true one, deg."""
    poses = read_poses(estimate).poses
    true_poses = read_poses(truth).poses
    present = [name for name in names if name in poses]
    errors = [rotation_angle_deg(poses[a][0] @ poses[b][0].T, true_poses[a][0] @ true_poses[b][0].T)
              for i, a in enumerate(present) for b in present[i + 1:]]
    return rms(errors)


def lens_errors(results: Path, truth: Mapping[str, Intrinsics]) -> dict[str, dict]:
    """Per camera of self_calibration.json: focal error and sigma (%), distortion error
    modulo a homography (px), coverage, and what was held."""
    reports = json.loads((results / SELF_CALIBRATION_FILE).read_text())["cameras"]
    refined = load_intrinsics_dir(results / "intrinsics")
    tracks = Tracks.read(results / "tracks.json")
    out = {}
    for name, report in reports.items():
        lens = refined[name]
        focal_pct = 100.0 * (lens.K[0, 0] / truth[name].K[0, 0] - 1.0)
        sigma = report.get("focal_sigma")
        sigma_pct = None if sigma is None else 100.0 * sigma / lens.K[0, 0]
        p99, worst = distortion_error(lens, truth[name], tracks.observations(name)[1])
        coverage = report.get("coverage")
        out[name] = {"observable": "focal" in report["refined"], "focal_pct": focal_pct, "sigma_pct": sigma_pct,
                     "dist_p99": p99, "dist_max": worst, "held": report["held"],
                     "observations": report["observations"], "coverage": math.nan if coverage is None else coverage}
    return out


def distortion_error(refined: Intrinsics, truth: Intrinsics, xy: np.ndarray) -> tuple[float, float]:
    """99th percentile and max of the lens error modulo a homography over the camera's
    raw pixels (``xy``: its observations undistorted with ``refined``)."""
    if len(xy) < 4:
        return math.nan, math.nan
    pixels = refined.distort_points(xy)
    a = refined.normalize(refined.undistort_points(pixels))
    b = truth.undistort_points(pixels)
    H, _ = cv2.findHomography(a, b, 0)
    if H is None:
        return math.nan, math.nan
    error = np.linalg.norm(cv2.perspectiveTransform(a.reshape(-1, 1, 2), H).reshape(-1, 2) - b, axis=1)
    return float(np.percentile(error, 99)), float(error.max())


def rms(values: list[float]) -> float:
    return float(np.sqrt(np.mean(np.square(values)))) if values else math.nan


def format_px(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def format_camera(name: str, camera: dict, runs: dict) -> str:
    sigma = "-" if camera["sigma_pct"] is None else f"{camera['sigma_pct']:.3f}"
    z = "-" if not camera["sigma_pct"] else f"{camera['focal_pct'] / camera['sigma_pct']:+.1f}"
    reasons: dict[str, list[str]] = {}
    for entry, why in camera["held"].items():
        reasons.setdefault(why, []).append(entry)
    held = "; ".join(f"{', '.join(entries)}: {why}" for why, entries in reasons.items())
    state = "refined" if camera["observable"] else "held"
    rotation = " ".join(f"{runs[label]['rot_deg'].get(name, math.nan):>7.3f}" for label in ("true", "refined"))
    seen = " ".join(f"{format_px(runs[label]['eval_seen_px'].get(name)):>6}" for label in ("true", "refined"))
    return (f"  {name:<8} {state:<8} {camera['observations']:>6} {camera['coverage']:>5.2f} "
            f"{camera['focal_pct']:>+8.3f} {sigma:>8} {z:>7} {camera['dist_p99']:>8.3f} {camera['dist_max']:>8.3f} "
            f"{rotation} {seen}  {held}")


def format_table(row: dict) -> str:
    lines = [f"{row['preset']} seed {row['seed']}",
             f"  {'camera':<8} {'focal':<8} {'obs':>6} {'cover':>5} {'err %':>8} {'sigma %':>8} {'err/sig':>7} "
             f"{'p99 px':>8} {'max px':>8} {'rot tru':>7} {'rot ref':>7} {'ev tru':>6} {'ev ref':>6}  held"]
    lines += [format_camera(name, camera, row["runs"]) for name, camera in row["cameras"].items()]
    lines.append("  (rot: deg after alignment on the centres; ev: mean evaluation error where the camera saw "
                 "the floor, px)")
    return "\n".join(lines)


def format_failed(runs: dict, key: str) -> str:
    """The cameras whose evaluation (``key``: eval_px or eval_seen_px) failed, per run."""
    parts = []
    for label in RUNS:
        failed = [f"{name} ({format_px(px)})" for name, px in runs[label][key].items() if not succeeded(px)]
        if failed:
            parts.append(f"{label}: {', '.join(failed)}")
    return f"  (failed, mean px: {'  '.join(parts)})" if parts else ""


def format_summary(row: dict) -> str:
    runs = row["runs"]
    pairs = "  ".join(f"{label} {runs[label]['rot_pairs']:.4f}" for label in RUNS)
    centre = "  ".join(f"{label} {runs[label]['rot_strong']:.4f}/{runs[label]['rot_all']:.4f}" for label in RUNS)
    full = "  ".join(f"{label} {100 * runs[label]['success']:.0f} %" for label in RUNS)
    seen = "  ".join(f"{label} {100 * runs[label]['success_seen']:.0f} %" for label in RUNS)
    kept = f"{runs['true']['eval_seen_n']}/{runs['true']['eval_n']} observations"
    weak = "  ".join(f"{label}: {', '.join(runs[label]['weak'])}" for label in RUNS if runs[label]["weak"])
    excluded = [name for name in runs["true"]["eval_seen_px"] if name not in seen_reference(row)]
    checks = criteria(row)
    return (f"  pairwise rot deg ({len(row['pair_cameras'])} cameras not weak with the true intrinsics, "
            f"observable): "
            f"{pairs}  ratio refined/true {pair_ratio(row):.2f}\n"
            f"  centre-aligned rot RMSE deg (not weak/all): {centre}  ratio refined/true {centre_ratio(row):.2f}\n"
            f"  eval @{SUCCESS_PX:g} px, all points: {full}" + format_failed(runs, "eval_px")
            + f"\n  eval @{SUCCESS_PX:g} px, where the floor was seen ({kept}): {seen}"
            + format_failed(runs, "eval_seen_px")
            + (f"\n  weak: {weak}" if weak else "")
            + f"\n  criteria: {'PASS' if all(checks.values()) else 'FAIL'} "
            + " ".join(f"{name}={'ok' if ok else 'FAIL'}" for name, ok in checks.items())
            + f"  (eval over the cameras declared observable, on every point; the restricted one over "
              f"those the true run passes, excluded: {', '.join(excluded) or 'none'})"
            + f"  ({row['seconds']:.0f} s)")


def rms_ratio(rows: list[dict], label: str) -> float:
    """RMS over the rows of a run's pairwise rotation error over the true run's."""
    return rms([row["runs"][label]["rot_pairs"] for row in rows]) / rms([row["runs"]["true"]["rot_pairs"] for row in rows])


def pair_ratio(row: dict) -> float:
    return row["runs"]["refined"]["rot_pairs"] / row["runs"]["true"]["rot_pairs"]


def centre_ratio(row: dict) -> float:
    return row["runs"]["refined"]["rot_strong"] / row["runs"]["true"]["rot_strong"]


def seen_reference(row: dict) -> list[str]:
    """The cameras whose restricted evaluation succeeds with the true intrinsics."""
    return [name for name, px in row["runs"]["true"]["eval_seen_px"].items() if succeeded(px)]


def seen_success(row: dict) -> float:
    """Fraction of ``seen_reference`` whose restricted evaluation succeeds when refined."""
    names = seen_reference(row)
    refined = row["runs"]["refined"]["eval_seen_px"]
    return sum(succeeded(refined.get(name)) for name in names) / len(names) if names else math.nan


def observable(row: dict) -> list[dict]:
    return [camera for camera in row["cameras"].values() if camera["observable"]]


def observable_success(row: dict) -> float:
    """Fraction of the cameras declared observable whose evaluation on every point
    succeeds with the refined intrinsics."""
    names = [name for name, camera in row["cameras"].items() if camera["observable"]]
    refined = row["runs"]["refined"]["eval_px"]
    return sum(succeeded(refined.get(name)) for name in names) / len(names) if names else math.nan


def criteria(row: dict) -> dict[str, bool]:
    cameras = observable(row)
    return {"focal": all(abs(c["focal_pct"]) <= MAX_FOCAL_PCT for c in cameras),
            "distortion": all(c["dist_p99"] <= MAX_DIST_PX for c in cameras),
            "pair_rotation": pair_ratio(row) <= MAX_ROT_RATIO,
            "eval": observable_success(row) >= 1.0}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--presets", default="or-full,demo",
                        help="comma-separated scene presets (default or-full,demo)")
    parser.add_argument("--seeds", type=int, default=1, help="seeds per preset (default 1)")
    parser.add_argument("--focal-error", type=float, default=0.08,
                        help="nominal focal = true focal x (1 + this) (default 0.08: 8 %% too long)")
    parser.add_argument("--noise-px", type=float, default=0.1,
                        help="noise of each observed coordinate, px (default 0.1, the real detector's centres)")
    parser.add_argument("--true-lens", choices=("full", "k1"), default="full",
                        help="the cameras' true lenses: the preset's whole lens (full, the default) or its k1 "
                             "alone (k1)")
    parser.add_argument("--entries", default="focal,k1,k2,k3,tangential",
                        help="lens entries refined (--refine-intrinsics; default focal,k1,k2,k3,tangential)")
    parser.add_argument("--work", type=Path, default=None,
                        help="keep simulations and results here (default: a temporary folder)")
    parser.add_argument("--json", type=Path, default=None, help="also write every row to this JSON file")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    presets = [name.strip() for name in args.presets.split(",") if name.strip()]
    rows = []
    with tempfile.TemporaryDirectory(prefix="self-calibration-") as scratch:
        work = args.work or Path(scratch)
        work.mkdir(parents=True, exist_ok=True)
        for preset in presets:
            for seed in range(args.seeds):
                started = time.perf_counter()
                row = run(preset, seed, work, args)
                row["seconds"] = time.perf_counter() - started
                rows.append(row)
                print(format_table(row) + "\n" + format_summary(row), flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    cameras = [camera for row in rows for camera in observable(row)]
    worst_focal = max((abs(c["focal_pct"]) for c in cameras), default=math.nan)
    worst_dist = max((c["dist_p99"] for c in cameras), default=math.nan)
    worst_pairs = max((pair_ratio(row) for row in rows), default=math.nan)
    worst_centre = max((centre_ratio(row) for row in rows), default=math.nan)
    success_observable = min((observable_success(row) for row in rows), default=math.nan)
    success_seen = min((seen_success(row) for row in rows), default=math.nan)
    success_all = min((row["runs"]["refined"]["success"] for row in rows), default=math.nan)
    z = [c["focal_pct"] / c["sigma_pct"] for c in cameras if c["sigma_pct"]]
    print(f"self-calibration: worst_focal_pct={worst_focal:.3f} worst_dist_px={worst_dist:.3f} "
          f"worst_pair_rot_ratio={worst_pairs:.2f} worst_centre_rot_ratio={worst_centre:.2f} "
          f"eval_success_observable={success_observable:.3f} eval_success_seen={success_seen:.3f} "
          f"eval_success_all={success_all:.3f} rms_pair_rot_ratio={rms_ratio(rows, 'refined'):.2f} "
          f"focal_only_rms_pair_rot_ratio={rms_ratio(rows, 'focal-only'):.2f} focal_z_rms={rms(z):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
