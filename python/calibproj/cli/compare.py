"""Compare estimated camera poses with a reference after Sim(3) alignment.

ESTIMATE is a camera_poses.json; TRUTH is a truth.json of a simulation or another
camera_poses.json. The estimate is aligned on the camera centres the two share
(Umeyama similarity); then every camera's rotation error (degrees) and centre error
(mm when both files are metric, and % of the mean inter-camera distance of TRUTH)
are reported, with their RMSE, and the cameras TRUTH has but ESTIMATE lacks.

With --json, prints {"rotation_rmse_deg", "translation_rmse_mm",
"translation_rmse_pct", "registered", "missing", "cameras": {name:
{"rotation_deg", "translation_mm", "translation_pct"}}}.
"""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("estimate", help="camera_poses.json to judge")
    parser.add_argument("truth", help="reference: truth.json or camera_poses.json")
    parser.add_argument("--json", action="store_true", help="print the result as JSON (for programs)")


def run(args: argparse.Namespace) -> int:
    import json

    from calibproj.evaluation.comparison import compare

    result = compare(args.estimate, args.truth)
    if args.json:
        print(json.dumps(result.to_json(), indent=1))
    else:
        print(format_table(result))
    return 0


def format_table(result) -> str:
    """A readable table of a ``calibproj.evaluation.comparison.Comparison``."""
    metric = result.translation_rmse_mm is not None
    header = f"{'camera':<16}{'rotation (deg)':>16}{'centre (mm)' if metric else '':>14}{'centre (%)':>13}"
    lines = [header, "-" * len(header)]
    for name, error in result.cameras.items():
        millimetres = f"{error.translation_mm:14.2f}" if metric else " " * 14
        lines.append(f"{name:<16}{error.rotation_deg:16.4f}{millimetres}{error.translation_pct:13.4f}")
    lines.append("-" * len(header))
    millimetres = f"{result.translation_rmse_mm:14.2f}" if metric else " " * 14
    lines.append(f"{'RMSE':<16}{result.rotation_rmse_deg:16.4f}{millimetres}{result.translation_rmse_pct:13.4f}")
    lines.append(f"registered {len(result.registered)} camera(s); missing: {', '.join(result.missing) or 'none'}")
    lines.append(f"mean inter-camera distance of the reference: {result.mean_camera_distance:.4g}")
    return "\n".join(lines)
