"""The operating table left in place: rendered videos of the demo room with and without it.

Per seed, one projection sequence is rendered in the demo room (``demo``) and in the same
room with its operating table and a cart left in the projection (``or-table``), both
calibrated from their videos (coplanar model, metric scale from far1's true height) and
compared with the truth. Per camera and room it prints the rotation error after Sim(3)
alignment (deg), whether the camera was reported weak, the MSMs kept by the ingest, how
many of them lie on the table top (from the truth), and how many kept centres are more
than 1 px from the true image point (markers cut by the table's edge or partly hidden by
it).

Per seed:

- rotation RMSE over the cameras weak in neither room, with and without the table, and
  their ratio (the issue asks <= 1.2);
- the planes found besides the floor and the table top's height error (mm, the issue
  asks <= 2);
- the table-top points of the calibration seen by two cameras or more, brought onto the
  truth's frame by the camera centres' alignment: largest and 99th percentile distance
  to the true top (mm, the issue asks <= 1).

The last line: ``or-table: registered=A/B worst_rot_ratio=.. worst_height_mm=..
worst_top_points_mm=.. biased_centres=..``.

    python tools/bench/or_table.py                 # one seed, 100 arrays (~10 min on 2 cores)
    python tools/bench/or_table.py --seeds 3 --work /tmp/or-table
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

from calibproj.evaluation.comparison import align_centers, compare
from calibproj.pipeline import calibrate
from calibproj.sequence import generate
from calibproj.simulate.render import simulate_videos
from calibproj.formats.tracks import Tracks

ROOMS = ("demo", "or-table")
TOP_M = 0.9  # the or-table preset's table top


def run_room(preset: str, sequence, folder: Path, seed: int) -> dict:
    room = folder / preset
    if not (room / "room" / "truth.json").exists():
        simulate_videos(preset, sequence, room / "room", seed=seed)
    truth = json.loads((room / "room" / "truth.json").read_text())
    height = truth["cameras"]["far1"]["center"][2]
    calibration = calibrate(room / "room" / "videos", room / "room" / "intrinsics",
                            sequence=folder / "sequence" / "sequence.json", out=room / "results", progress=False,
                            scale=f"camera-height:far1={height}", force=True, report=False)
    errors = compare(room / "results" / "camera_poses.json", room / "room" / "truth.json")
    return {"truth": truth, "calibration": calibration, "errors": errors,
            "tracks": Tracks.read(room / "results" / "tracks.json")}


def camera_rows(result: dict) -> dict[str, dict]:
    truth, calibration, tracks = result["truth"], result["calibration"], result["tracks"]
    heights = np.asarray(truth["points"]["xyz"])[:, 2]
    rows = {}
    for index, name in enumerate(tracks.camera_names):
        mine = tracks.camera_index == index
        ids = tracks.point_ids[tracks.point_index[mine]]
        seen = truth["image_points"][name]
        true_xy = dict(zip(seen["ids"], np.asarray(seen["undistorted"]).reshape(-1, 2)))
        errors = [float(np.linalg.norm(xy - true_xy[int(i)])) for i, xy in zip(ids, tracks.xy[mine])
                  if int(i) in true_xy]
        rows[name] = {
            "rotation_deg": result["errors"].cameras[name].rotation_deg if name in result["errors"].cameras else None,
            "weak": bool(calibration.metrics[name].weak) if name in calibration.metrics else None,
            "msms": int(mine.sum()),
            "on_top": int((heights[ids] > 0.5 * TOP_M).sum()),
            "biased": int(sum(error > 1.0 for error in errors)),
        }
    return rows


def top_points_mm(result: dict) -> tuple[float, float, int]:
    """Largest and 99th percentile distance (mm) to the true top of the table-top points
    seen by two registered cameras or more, and their number."""
    truth, calibration, tracks = result["truth"], result["calibration"], result["tracks"]
    names = calibration.registered
    scale, R, t = align_centers(np.array([calibration.center(n) for n in names]),
                                np.array([truth["cameras"][n]["center"] for n in names]))
    # Views by registered cameras: a point one of them sees lies where its ray meets the floor.
    by_registered = np.isin(np.asarray(tracks.camera_names)[tracks.camera_index], names)
    views = dict(zip(*np.unique(tracks.point_ids[tracks.point_index[by_registered]], return_counts=True)))
    heights = np.asarray(truth["points"]["xyz"])[:, 2]
    ids = np.asarray(calibration.point_ids)
    on_top = (heights[ids] > 0.5 * TOP_M) & (np.array([views.get(int(i), 0) for i in ids]) >= 2)
    if not on_top.any():
        return math.inf, math.inf, 0
    z = (scale * calibration.points[on_top] @ R.T + t)[:, 2]
    distance = 1e3 * np.abs(z - TOP_M)
    return float(distance.max()), float(np.percentile(distance, 99)), int(on_top.sum())


def rmse(values: list[float]) -> float:
    return float(np.sqrt(np.mean(np.square(values)))) if values else math.nan


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=1, help="seeds (default 1)")
    parser.add_argument("--arrays", type=int, default=100, help="arrays of the sequence (default 100)")
    parser.add_argument("--work", type=Path, default=None,
                        help="folder for the videos and results, kept (default: a temporary one)")
    parser.add_argument("--json", type=Path, default=None, help="also write every row to this JSON file")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    work = args.work or Path(tempfile.mkdtemp(prefix="or-table-"))
    registered = cameras = biased = 0
    worst_ratio = worst_height = worst_top = 0.0
    rows = []
    for seed in range(args.seeds):
        folder = work / f"seed{seed}"
        sequence = generate(folder / "sequence", markers="aruco:4X4_50", arrays=args.arrays, video=False)
        results = {preset: run_room(preset, sequence, folder, seed) for preset in ROOMS}
        per_room = {preset: camera_rows(results[preset]) for preset in ROOMS}
        print(f"seed {seed}: camera  " + "  ".join(f"{p}: rot deg / weak / MSMs / on top / >1px" for p in ROOMS))
        for name in per_room["demo"]:
            cells = []
            for preset in ROOMS:
                row = per_room[preset][name]
                rotation = "failed" if row["rotation_deg"] is None else f"{row['rotation_deg']:.4f}"
                cells.append(f"{rotation:>8} {'weak' if row['weak'] else '    '} {row['msms']:5d} {row['on_top']:5d} "
                             f"{row['biased']:4d}")
            print(f"  {name:8s} " + "   ".join(cells))
        strong = [n for n in per_room["demo"] if all(per_room[p][n]["weak"] is False for p in ROOMS)]
        rmse_room = {p: rmse([per_room[p][n]["rotation_deg"] for n in strong]) for p in ROOMS}
        ratio = rmse_room["or-table"] / rmse_room["demo"]
        table = results["or-table"]["calibration"]
        heights = [plane.offset for plane in table.planes]
        height_mm = min((1e3 * abs(h - TOP_M) for h in heights), default=math.inf)
        top_max, top_p99, top_count = top_points_mm(results["or-table"])
        print(f"  rotation RMSE over {', '.join(strong)}: demo {rmse_room['demo']:.4f}, or-table "
              f"{rmse_room['or-table']:.4f} deg, ratio {ratio:.2f}")
        print(f"  planes besides the floor: {', '.join(f'{h:.4f} m' for h in heights) or 'none'}; table top "
              f"{height_mm:.2f} mm off; its {top_count} points seen twice: max {top_max:.2f} mm, p99 {top_p99:.2f} mm",
              flush=True)
        registered += len(table.registered)
        cameras += len(per_room["or-table"])
        biased += sum(row["biased"] for row in per_room["or-table"].values())
        worst_ratio, worst_height, worst_top = max(worst_ratio, ratio), max(worst_height, height_mm), max(worst_top,
                                                                                                      top_max)
        rows.append({"seed": seed, "cameras": per_room, "rmse_deg": rmse_room, "ratio": ratio, "planes": heights,
                     "height_error_mm": height_mm, "top_points_max_mm": top_max, "top_points_p99_mm": top_p99})
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    print(f"or-table: registered={registered}/{cameras} worst_rot_ratio={worst_ratio:.2f} "
          f"worst_height_mm={worst_height:.2f} worst_top_points_mm={worst_top:.2f} biased_centres={biased}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
