"""Calibrate the cameras: register every camera and refine, then write the results.

From tracks (e.g. of `calibproj simulate --tracks-only` or `calibproj detect`):
    calibproj calibrate --tracks tracks.json --intrinsics INTRINSICS_DIR --out RESULTS_DIR

Writes camera_poses.json (world-to-camera poses in the floor frame: z up, floor z = 0),
metrics.json (per camera: mean and std reprojection error, inliers, view score, or why
it failed) and points.ply. An existing results folder is only overwritten with --force.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from calibproj.commands.options import add_dataclass_arguments, dataclass_from_args

RESULT_FILES = ("camera_poses.json", "metrics.json", "points.ply")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from calibproj.registration import RegistrationOptions

    parser.add_argument("--tracks", required=True, metavar="FILE", help="tracks.json to calibrate from")
    parser.add_argument("--intrinsics", required=True, metavar="DIR", help="folder of per-camera intrinsics files")
    parser.add_argument("--out", required=True, metavar="DIR", help="results folder")
    parser.add_argument("--force", action="store_true", help="overwrite the results of an earlier run in --out")
    parser.add_argument("--json", action="store_true", help="print the per-camera summary as JSON")
    add_dataclass_arguments(parser, RegistrationOptions, "registration options")


def check_output_folder(out: Path, force: bool) -> None:
    existing = [name for name in RESULT_FILES if (out / name).exists()]
    if existing and not force:
        raise ValueError(f"{out}: already holds results ({', '.join(existing)}); use --force to overwrite them")


def run(args: argparse.Namespace) -> int:
    import json

    from calibproj.calibration import calibration_summary
    from calibproj.io.intrinsics import load_intrinsics_dir
    from calibproj.registration import RegistrationOptions, calibrate
    from calibproj.tracks import Tracks

    out = Path(args.out)
    check_output_folder(out, args.force)
    tracks = Tracks.read(args.tracks)
    intrinsics = load_intrinsics_dir(args.intrinsics)
    options = dataclass_from_args(RegistrationOptions, args)
    calibration = calibrate(tracks, intrinsics, options)
    calibration.save(out)
    rows = calibration_summary(calibration)
    if args.json:
        print(json.dumps(rows, indent=1))
    else:
        print(format_summary(rows))
        print(f"results in {out} (unit: {calibration.unit})")
    return 0 if calibration.registered else 1


def format_summary(rows: list[dict]) -> str:
    header = f"{'camera':<14}{'status':<12}{'mean px':>9}{'std px':>9}{'inliers':>9}{'track>=2':>10}{'score':>9}"
    lines = [header, "-" * len(header)]
    for row in rows:
        if row["registered"]:
            lines.append(
                f"{row['camera']:<14}{'registered':<12}{row['mean_px']:9.3f}{row['std_px']:9.3f}"
                f"{row['inliers']:9d}{row['track2']:10d}{row['view_score']:9d}"
            )
        else:
            lines.append(f"{row['camera']:<14}{'FAILED':<12}{row['failure']}")
    return "\n".join(lines)
