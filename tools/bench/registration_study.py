"""Registration accuracy and speed over many simulated scenes, FREE vs COPLANAR.

For each scene preset and seed: a tracks-only simulation (noise in px, optional gross
outliers), a calibration with each model (with the projector model, as ``calibrate``
runs it with a sequence: every MSM's projector pixel from the layout; ``--no-projector``
leaves it out), and the Sim(3)-aligned pose errors against the truth. Prints per preset and model: success rate (every camera registered and
the errors within the bounds), rotation and translation RMSE statistics (median, 95th
percentile, max), and the calibration time (median, single thread).

    python tools/bench/registration_study.py --scenes paper,or-full --seeds 100
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from calibproj.evaluation.comparison import compare
from calibproj.formats.poses import CameraPoses
from calibproj.registration.driver import RegistrationOptions, register
from calibproj.sequence.projected import layout_markers
from calibproj.simulate import simulate_tracks


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", default="paper,or-full", help="comma-separated presets (default paper,or-full)")
    parser.add_argument("--models", default="free,coplanar", help="comma-separated models (default free,coplanar)")
    parser.add_argument("--seeds", type=int, default=100, help="number of seeds per scene (default 100)")
    parser.add_argument("--first-seed", type=int, default=0, help="first seed (default 0)")
    parser.add_argument("--noise", type=float, default=0.5, help="observation noise in px (default 0.5)")
    parser.add_argument("--outliers", type=float, default=0.0, help="fraction of gross outliers (default 0)")
    parser.add_argument("--max-rotation-deg", type=float, default=0.02, help="success bound (default 0.02)")
    parser.add_argument("--max-translation-pct", type=float, default=0.05, help="success bound (default 0.05)")
    parser.add_argument("--no-projector", action="store_true",
                        help="calibrate without the projector model (tracks alone)")
    return parser.parse_args()


def percentile_line(values: list[float]) -> str:
    return f"median {np.median(values):.4f}  p95 {np.percentile(values, 95):.4f}  max {np.max(values):.4f}"


def main() -> None:
    args = parse_args()
    print(f"noise {args.noise} px, outliers {args.outliers:.0%}, seeds {args.first_seed}..{args.first_seed + args.seeds - 1}, "
          f"{'without' if args.no_projector else 'with'} the projector model")
    summary = []
    for scene in args.scenes.split(","):
        results = {model: {"rotation": [], "translation": [], "time": [], "ok": 0, "all": 0} for model in args.models.split(",")}
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            sim = simulate_tracks(scene, None, noise_px=args.noise, seed=seed, outlier_fraction=args.outliers)
            truth = CameraPoses({c.name: (c.R, c.t) for c in sim.scene.cameras}, "m")
            projector = None if args.no_projector else layout_markers(sim.layout)
            for model, r in results.items():
                start = time.perf_counter()
                calibration = register(sim.tracks, sim.intrinsics, RegistrationOptions(model=model, seed=seed),
                                       projector=projector)
                r["time"].append(time.perf_counter() - start)
                everything = not calibration.failed and len(calibration.registered) == len(sim.scene.cameras)
                r["all"] += everything
                if len(calibration.registered) < 3:
                    r["rotation"].append(float("inf"))
                    r["translation"].append(float("inf"))
                    continue
                errors = compare(CameraPoses(calibration.poses, calibration.unit, calibration.failed), truth)
                r["rotation"].append(errors.rotation_rmse_deg)
                r["translation"].append(errors.translation_rmse_pct)
                r["ok"] += everything and errors.rotation_rmse_deg < args.max_rotation_deg and (
                    errors.translation_rmse_pct < args.max_translation_pct)
        for model, r in results.items():
            n = len(r["time"])
            print(f"\n{scene} {model}: {n} scenes")
            print(f"  all cameras registered: {r['all'] / n:.0%}; within bounds: {r['ok'] / n:.0%}")
            print(f"  rotation RMSE (deg):        {percentile_line(r['rotation'])}")
            print(f"  translation RMSE (% dist):  {percentile_line(r['translation'])}")
            print(f"  calibrate time (s):         median {statistics.median(r['time']):.3f}  max {max(r['time']):.3f}")
            summary.append(
                f"registration {scene} {model}: success={r['ok'] / n:.2f} registered_all={r['all'] / n:.2f} "
                f"rot_rmse_median_deg={np.median(r['rotation']):.4f} trans_rmse_median_pct={np.median(r['translation']):.4f} "
                f"time_median_s={statistics.median(r['time']):.3f}"
            )
    print()
    for line in summary:
        print(line)


if __name__ == "__main__":
    main()
