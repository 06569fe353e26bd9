"""Check and repair on rendered rooms: cameras moved, turned and re-zoomed between the
calibration and a check projection, with the renderer's realistic effects on.

Per scene and seed the room is rendered with the full projection and calibrated (with
--densify, as a user with a weak zoomed camera does: the extra projection `generate
--densify` plans rendered and merged); the check projection (`calibproj generate
--check`) is planned from that calibration. Each
trial then changes 0-3 cameras (rotations 0.02-2 deg, centre moves 1-50 mm, both
log-uniform) and at most one camera's zoom (1-5 %), renders the check projection in the
changed room, and runs `calibproj check --out` on it. With --full, the changed room is
also rendered with the full projection and calibrated from scratch: the reference
for the repaired poses' accuracy and for the time.

Per trial it prints the truth (each changed camera: rotation, centre move, zoom, and how
far the change moves the working volume in its image) and the verdicts. A camera
should be flagged when its true change moves the working volume (floor to 2 m) by
more than the tolerance in its image. The last line:
``check: false_moved=.. missed_moved=.. missed_below_tolerance=.. repaired_rot_ratio=..
check_time_ratio=..``: unchanged cameras flagged, cameras over the tolerance not flagged
with the right status, changes under the tolerance not flagged (expected), the worst
ratio of the repaired calibration's rotation RMSE to the full calibration's (both RMSEs,
rotation and centre, are in each trial's row), and the check's wall time over the full
calibration's.

    python tools/bench/check_repair.py --scenes demo,or-full --seeds 3 --trials 5 --full --densify
    python tools/bench/check_repair.py --scenes demo --seeds 1 --trials 2 --arrays 12
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from realism import CONDITIONS, calibrate_scaled  # noqa: E402

from calibproj.formats.calibration import Calibration  # noqa: E402
from calibproj.check.repair import CheckOptions, UntrustedReference, check  # noqa: E402
from calibproj.evaluation.comparison import CameraPoses, compare  # noqa: E402
from calibproj.cli.demo_room import marker_side_on_floor  # noqa: E402
from calibproj.registration.driver import RegistrationOptions  # noqa: E402
from calibproj.sequence import Sequence, generate  # noqa: E402
from calibproj.sequence.check_sequence import plan_check  # noqa: E402
from calibproj.sequence.densify import DensifyOptions, densify  # noqa: E402
from calibproj.simulate.render import RenderOptions, simulate_videos  # noqa: E402
from calibproj.simulate.scene import CameraChange, Scene, load_scene  # noqa: E402

# The effects, and frame-time jitter with a few dropped frames: real cameras are
# not phase-locked to the projector.
EFFECTS = ("rolling-15ms", "room-light", "floor", "drops-2")
VOLUME_HEIGHT_M = 2.0


def realistic(scene: Scene) -> Scene:
    for name in EFFECTS:
        scene = CONDITIONS[name][0](scene)
    return scene


def draw_changes(names: list[str], rng: np.random.Generator) -> dict[str, CameraChange]:
    """0-3 cameras moved (rotation 0.02-2 deg, centre 1-50 mm) and at most one re-zoomed (1-5 %)."""
    changes: dict[str, CameraChange] = {}
    for name in rng.choice(names, size=int(rng.integers(0, 4)), replace=False):
        angle = math.exp(rng.uniform(math.log(0.02), math.log(2.0)))
        direction = rng.uniform(0.0, 2.0 * math.pi)
        shift = math.exp(rng.uniform(math.log(0.001), math.log(0.05)))
        axis = rng.normal(size=3)
        changes[str(name)] = CameraChange(pan_deg=angle * math.cos(direction), tilt_deg=angle * math.sin(direction),
                                          shift_m=tuple((shift * axis / np.linalg.norm(axis)).tolist()))
    if rng.random() < 0.5:
        name = str(rng.choice(names))
        zoom = 1.0 + rng.choice([-1.0, 1.0]) * rng.uniform(0.01, 0.05)
        changes[name] = replace(changes.get(name, CameraChange()), zoom=zoom)
    return changes


def volume_shift_px(before, after, floor_size_m: tuple[float, float]) -> float:
    """How far a change moves the working volume (the floor, up to 2 m) in the camera's
    image, at most: the truth the check's practical test estimates."""
    xs = np.linspace(-floor_size_m[0] / 2, floor_size_m[0] / 2, 25)
    ys = np.linspace(-floor_size_m[1] / 2, floor_size_m[1] / 2, 25)
    zs = np.linspace(0.0, VOLUME_HEIGHT_M, 5)
    points = np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), axis=-1).reshape(-1, 3)

    def pixels(camera) -> np.ndarray:
        local = points @ camera.R.T + camera.t
        projected = local @ camera.K.T
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = projected[:, :2] / projected[:, 2:]
        return np.where(local[:, 2:] > 0.1, xy, np.nan)

    first, second = pixels(before), pixels(after)
    width, height = before.resolution
    inside = np.all(np.isfinite(first), axis=1) & (first[:, 0] >= 0) & (first[:, 1] >= 0) & \
        (first[:, 0] <= width) & (first[:, 1] <= height) & np.all(np.isfinite(second), axis=1)
    return float(np.max(np.linalg.norm(first[inside] - second[inside], axis=1))) if inside.any() else 0.0


def rotation_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(a @ b.T) - 1.0) / 2.0, -1.0, 1.0))))


def accuracy(folder: Path, scene: Scene) -> tuple[float, float]:
    """Rotation (deg) and centre (mm) RMSE of a results folder against the scene's truth."""
    calibration = Calibration.load(folder)
    truth = CameraPoses({c.name: (c.R, c.t) for c in scene.cameras}, "m")
    comparison = compare(CameraPoses(calibration.poses, calibration.unit, calibration.failed), truth)
    return comparison.rotation_rmse_deg, comparison.translation_rmse_mm


def calibrated_room(scene: Scene, sequence, sequence_path: Path, folder: Path, seed: int,
                    densify_for_weak: bool, reuse: bool = False) -> tuple[Path, list, float]:
    """The room rendered with the full projection and calibrated (metric), and with
    ``densify_for_weak`` the extra projection `generate --densify` plans rendered and
    merged, as a user with a weak zoomed camera does: the results folder, the sequences
    it was calibrated from, and the seconds spent calibrating (ingest included, the
    rendering not). With ``reuse``, a room calibrated by an earlier run is taken as it
    is (its seconds then unknown: nan)."""
    if reuse and (folder / "results").is_dir():
        sequences = [Sequence.load(sequence_path)]
        if densify_for_weak and (folder / "results_dense").is_dir():
            return folder / "results_dense", sequences + [Sequence.load(folder / "dense_sequence.json")], math.nan
        if not densify_for_weak:
            return folder / "results", sequences, math.nan
    simulate_videos(scene, sequence, folder, seed=seed, options=RenderOptions())
    scale = f"marker-size:{marker_side_on_floor(folder / 'scene.json', sequence):.9f}"
    results = folder / "results"
    started = time.perf_counter()
    calibrate_scaled(folder / "videos", sequence_path, results, intrinsics=folder / "intrinsics", scale=scale,
                     options=RegistrationOptions(), exposures=None, label=folder.name)
    seconds = time.perf_counter() - started
    sequences = [Sequence.load(sequence_path)]
    if not densify_for_weak:
        return results, sequences, seconds
    dense, _ = densify(results, sequences[0], DensifyOptions())
    if dense is None:
        return results, sequences, seconds
    dense.save(folder / "dense_sequence.json")
    simulate_videos(scene, dense, folder / "dense", seed=seed + 1000, options=RenderOptions())
    started = time.perf_counter()
    calibrate_scaled(folder / "dense" / "videos", folder / "dense_sequence.json", folder / "results_dense",
                     intrinsics=folder / "intrinsics", scale=scale, options=RegistrationOptions(), exposures=None,
                     label=folder.name, merge=results)
    return folder / "results_dense", sequences + [dense], seconds + time.perf_counter() - started


def trial(scene: Scene, changes: dict[str, CameraChange], results: Path, check_path: Path, sequence,
          sequence_path: Path, folder: Path, seed: int, args) -> dict:
    changed = scene.changed(changes)
    check_sequence = Sequence.load(check_path)
    simulate_videos(changed, check_sequence, folder / "check", seed=seed, options=RenderOptions())
    options = CheckOptions(tolerance_px=args.tolerance_px)
    started = time.perf_counter()
    try:
        result = check(results, folder / "check" / "videos", sequence=check_path, out=folder / "repaired",
                       options=options, force=True, report=False, progress=False)
        repaired = folder / "repaired"
    except UntrustedReference as error:
        result, repaired = error.result, None
    check_s = time.perf_counter() - started
    row = {"changes": {}, "verdicts": {n: v.status for n, v in result.cameras.items()}, "check_s": check_s,
           "trusted": result.trusted}
    for camera in scene.cameras:
        change = changes.get(camera.name)
        after = changed.camera(camera.name)
        row["changes"][camera.name] = {
            "rotation_deg": rotation_deg(camera.R, after.R),
            "centre_mm": 1000.0 * float(np.linalg.norm(camera.center - after.center)),
            "zoom": after.fx / camera.fx, "shift_px": volume_shift_px(camera, after, scene.floor.size_m),
            "changed": change is not None}
    if repaired is not None:
        row["repaired_rot"], row["repaired_mm"] = accuracy(repaired, changed)
    if args.full:
        # The same work as the first calibration; its time is the ingest's and
        # calibration's (the rendering's left out).
        full, _, row["full_s"] = calibrated_room(changed, sequence, sequence_path, folder / "full", seed + 500,
                                                 args.densify)
        row["full_rot"], row["full_mm"] = accuracy(full, changed)
    return row


def score(row: dict, tolerance_px: float, calibrated: list[str]) -> dict[str, int]:
    """Verdicts against the truth, over the cameras of the stored calibration."""
    counts = {"false_moved": 0, "missed_moved": 0, "missed_below_tolerance": 0}
    for name, truth in row["changes"].items():
        if name not in calibrated:
            continue
        status = row["verdicts"].get(name)
        flagged = status in ("moved", "rezoomed")
        if not truth["changed"]:
            counts["false_moved"] += flagged
            continue
        expected = "rezoomed" if abs(truth["zoom"] - 1.0) > 1e-9 else "moved"
        if truth["shift_px"] > tolerance_px:
            counts["missed_moved"] += status != expected
        else:
            counts["missed_below_tolerance"] += not flagged
    return counts


def format_trial(label: str, row: dict) -> str:
    parts = []
    for name, truth in row["changes"].items():
        if truth["changed"]:
            parts.append(f"{name} {truth['rotation_deg']:.3f} deg {truth['centre_mm']:.1f} mm "
                         f"zoom {100 * (truth['zoom'] - 1):+.1f} % ({truth['shift_px']:.2f} px) -> "
                         f"{row['verdicts'].get(name)}")
    others = [name for name, truth in row["changes"].items() if not truth["changed"]]
    flagged = [name for name in others if row["verdicts"].get(name) in ("moved", "rezoomed")]
    line = f"{label}: " + ("; ".join(parts) or "nothing changed")
    line += f" | unchanged {len(others) - len(flagged)}/{len(others)}" + (f" (flagged: {flagged})" if flagged else "")
    if "repaired_rot" in row:
        line += f" | repaired {row['repaired_rot']:.4f} deg {row['repaired_mm']:.2f} mm"
    if "full_rot" in row:
        line += (f" | full {row['full_rot']:.4f} deg {row['full_mm']:.2f} mm"
                 f" | time {row['check_s']:.0f}/{row['full_s']:.0f} s")
    return line + ("" if row["trusted"] else " | untrusted")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", default="demo,or-full", help="scene presets (default demo,or-full)")
    parser.add_argument("--seeds", type=int, default=3, help="seeds per scene (default 3)")
    parser.add_argument("--first-seed", type=int, default=0,
                        help="first seed; seeds first..first+N-1 are run (default 0)")
    parser.add_argument("--trials", type=int, default=5, help="trials per scene and seed (default 5)")
    parser.add_argument("--arrays", type=int, default=48, help="MSM arrays of the full projection (default 48)")
    parser.add_argument("--tolerance-px", type=float, default=CheckOptions.tolerance_px,
                        help="the check's tolerance (default %(default)s)")
    parser.add_argument("--full", action="store_true",
                        help="also render and calibrate every changed room with the full projection (slow)")
    parser.add_argument("--work", type=Path, default=None, help="keep renderings here (default: a temporary folder)")
    parser.add_argument("--densify", action="store_true",
                        help="calibrate every room as a user with a weak zoomed camera does: with the extra "
                             "projection `generate --densify` plans, merged (the full calibrations too)")
    parser.add_argument("--reuse", action="store_true",
                        help="take the rooms a run with the same --work calibrated as they are (the check "
                             "projection and the trials are planned and rendered again)")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    with tempfile.TemporaryDirectory(prefix="check-") as temporary:
        work = args.work or Path(temporary)
        sequence = generate(work / "sequence", arrays=args.arrays, scales=(1.0, 3.0, 6.0), video=False)
        sequence_path = work / "sequence" / "sequence.json"
        totals = {"false_moved": 0, "missed_moved": 0, "missed_below_tolerance": 0}
        rot_ratios, time_ratios, rows = [], [], []
        for scene_name in args.scenes.split(","):
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                scene = realistic(load_scene(scene_name, seed=seed))
                room = work / f"{scene_name}-{seed}"
                results, sequences, _ = calibrated_room(scene, sequence, sequence_path, room, seed, args.densify,
                                                        reuse=args.reuse)
                check_sequence, _, _ = plan_check(results, sequences)
                check_path = room / "check_sequence.json"
                check_sequence.save(check_path)
                print(f"{scene_name} seed {seed}: check projection {check_sequence.duration_s:.1f} s "
                      f"(full {sequence.duration_s:.1f} s)", flush=True)
                for k in range(args.trials):
                    rng = np.random.default_rng([seed, k, len(scene_name)])
                    changes = draw_changes(scene.camera_names, rng)
                    row = trial(scene, changes, results, check_path, sequence, sequence_path, room / f"trial-{k}",
                                seed * 100 + k + 1, args)
                    rows.append(row)
                    calibrated = list(Calibration.load(results).poses)
                    for key, value in score(row, args.tolerance_px, calibrated).items():
                        totals[key] += value
                    if "full_rot" in row and "repaired_rot" in row:
                        rot_ratios.append(row["repaired_rot"] / max(row["full_rot"], 1e-9))
                        time_ratios.append(row["check_s"] / row["full_s"])
                    print(format_trial(f"{scene_name} seed {seed} trial {k}", row), flush=True)
        if args.work:
            (args.work / "check_repair.json").write_text(json.dumps(rows, indent=1))
        ratio = max(rot_ratios) if rot_ratios else math.nan
        time_ratio = max(time_ratios) if time_ratios else math.nan
        print(f"check: false_moved={totals['false_moved']} missed_moved={totals['missed_moved']} "
              f"missed_below_tolerance={totals['missed_below_tolerance']} repaired_rot_ratio={ratio:.2f} "
              f"check_time_ratio={time_ratio:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
