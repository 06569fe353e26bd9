"""Calibrate the cameras: register every camera and refine, then write the results.

From tracks (e.g. of `calibproj simulate --tracks-only` or `calibproj detect`):
    calibproj calibrate --tracks tracks.json --intrinsics INTRINSICS_DIR --out RESULTS_DIR

Writes camera_poses.json (world-to-camera poses in the floor frame: z up, floor z = 0),
metrics.json (per camera: mean and std reprojection error, inliers, view score, or why
it failed) and points.ply. An existing results folder is only overwritten with --force.
The intrinsics used are copied into RESULTS_DIR/intrinsics/ (so that evaluate and the
report need nothing else), and report.html with report/*.png is written unless
--no-report.

Metric scale (--scale; without it the unit is arbitrary, the first camera at height 1):
    camera-height:NAME=METRES          height of a camera's optical centre above the floor
    distance:CAM_A,CAM_B=METRES        distance between two cameras' optical centres
    marker-size:[ARRAY/MARKER=]METRES  side of a projected marker at scale 1 on the floor
                                       (default: the marker nearest the image centre;
                                       needs --sequence)

Exports (--export yaml,colmap,anipose): calibration_opencv.yaml (cv2.FileStorage),
colmap/{cameras,images,points3D}.txt (COLMAP text model), calibration.toml (aniposelib).
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
    parser.add_argument("--scale", metavar="MEASUREMENT",
                        help="metric scale from one measurement (see above; default: arbitrary unit)")
    parser.add_argument("--sequence", metavar="FILE",
                        help="sequence.json of the projection (needed by --scale marker-size)")
    parser.add_argument("--export", metavar="FORMATS",
                        help="also write the calibration as yaml, colmap and/or anipose (comma-separated)")
    parser.add_argument("--no-report", action="store_true", help="do not write report.html and report/*.png")
    add_dataclass_arguments(parser, RegistrationOptions, "registration options")


def check_output_folder(out: Path, force: bool) -> None:
    existing = [name for name in RESULT_FILES if (out / name).exists()]
    if existing and not force:
        raise ValueError(f"{out}: already holds results ({', '.join(existing)}); use --force to overwrite them")


def run(args: argparse.Namespace) -> int:
    import json

    from calibproj.calibration import calibration_summary
    from calibproj.export import export_all, parse_formats
    from calibproj.io.intrinsics import load_intrinsics_dir, write_intrinsics_dir
    from calibproj.registration import RegistrationOptions, calibrate
    from calibproj.report import write_report
    from calibproj.scale import apply_scale, check_measurement, parse_scale, read_projected_markers
    from calibproj.tracks import Tracks

    out = Path(args.out)
    check_output_folder(out, args.force)
    measurement = parse_scale(args.scale) if args.scale else None
    if measurement is not None and measurement.kind == "marker-size" and args.sequence is None:
        raise ValueError(f"--scale {args.scale}: marker-size needs --sequence (the projection's sequence.json)")
    formats = parse_formats(args.export) if args.export else []
    tracks = Tracks.read(args.tracks)
    intrinsics = load_intrinsics_dir(args.intrinsics)
    markers = read_projected_markers(args.sequence, tracks.markers_per_array) if args.sequence else None
    if measurement is not None:
        check_measurement(measurement, tracks.camera_names, markers)
    options = dataclass_from_args(RegistrationOptions, args)
    calibration = calibrate(tracks, intrinsics, options)
    used = {name: intrinsics[name] for name in tracks.camera_names if name in intrinsics}
    write_intrinsics_dir(out / "intrinsics", used)
    if measurement is not None:
        try:
            calibration = apply_scale(calibration, measurement, markers)
        except ValueError as error:
            calibration.save(out)
            raise ValueError(f"{error}; results written to {out} in arbitrary units") from None
    calibration.save(out)
    export_all(calibration, formats, out, used, tracks)
    if not args.no_report:
        write_report(out, tracks, used)
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
