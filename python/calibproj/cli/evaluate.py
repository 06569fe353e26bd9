"""Evaluate a calibration on independent observations (paper section 3.2).

RESULTS is a folder written by `calibproj calibrate`; --tracks an eval_tracks.json of
points that took no part in the calibration (e.g. of `calibproj simulate --tracks-only`).
With the calibrated poses fixed, every evaluation point seen by two registered cameras
or more is triangulated (from the camera pair whose rays meet closest to a right
angle), all points are refined together by bundle adjustment, and each camera's
reprojection errors are reported. The success rate at a threshold is the percentage
of cameras whose mean error is below it; cameras that failed to register count as
failures. The intrinsics default to RESULTS/intrinsics; a camera whose intrinsics file
is bad or missing is left out, the file and the problem reported (exit status 1).

With --json, prints {"success_rate": {"0.5": f, "2": f, "5": f}, "cameras": {name:
{"mean_px", "std_px", "n"}}} (percentages; null errors for a camera without any).
"""

from __future__ import annotations

import argparse

from calibproj.cli.options import add_dataclass_arguments, dataclass_from_args


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from calibproj.evaluation.independent import EvaluationOptions

    parser.add_argument("results", metavar="RESULTS", help="results folder of calibproj calibrate")
    parser.add_argument("--tracks", required=True, metavar="FILE", help="evaluation observations (eval_tracks.json)")
    parser.add_argument("--intrinsics", metavar="DIR",
                        help="per-camera intrinsics folder (default: RESULTS/intrinsics)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON (for programs)")
    parser.add_argument("--save", action="store_true",
                        help="also write RESULTS/evaluation.json and show it in RESULTS/report.html")
    add_dataclass_arguments(parser, EvaluationOptions, "evaluation options")


def run(args: argparse.Namespace) -> int:
    import json
    import sys
    from pathlib import Path

    from calibproj.evaluation.independent import EvaluationOptions, evaluate

    if not Path(args.results).is_dir():
        raise FileNotFoundError(f"{args.results}: no such results folder")
    options = dataclass_from_args(EvaluationOptions, args)
    # --save changes the results folder as calibrate writes it: locked before the
    # evaluation (a calibrate --force on it fails at once, as this does beside one),
    # copied with the evaluation and the new report into a staging folder that replaces
    # it whole; a failure or an interruption leaves it as it was.
    folder = _locked_results(args.results) if args.save else None
    try:
        evaluation = evaluate(args.results, args.tracks, args.intrinsics, options)
        if folder is not None:
            _save_into(folder, args, evaluation, options)
    finally:
        if folder is not None:
            folder.abort()  # nothing left to do after a commit
    if args.json:
        print(json.dumps(evaluation.to_json(), indent=1))
    else:
        print(format_table(evaluation))
    if evaluation.unusable_intrinsics:
        failures = "; ".join(f"{name}: {reason}" for name, reason in evaluation.unusable_intrinsics.items())
        print(f"calibproj evaluate: {len(evaluation.unusable_intrinsics)} camera(s) without usable intrinsics: "
              f"{failures}", file=sys.stderr)
        return 1
    return 0


def _locked_results(results: str):
    from calibproj.formats.output_folder import OutputFolder
    from calibproj.formats.results import CALIBRATION_FILES

    return OutputFolder(results, force=True, signature=CALIBRATION_FILES).open()


def _save_into(folder, args: argparse.Namespace, evaluation, options) -> None:
    import shutil

    from calibproj.formats.file_names import path_as_recorded
    from calibproj.report import write_report

    with folder.writing() as staging:
        shutil.copytree(folder.path, staging, symlinks=True, dirs_exist_ok=True)
        evaluation.save(staging, path_as_recorded(args.tracks, args.results), options)
        write_report(staging, intrinsics=args.intrinsics)
    folder.commit()


def format_table(evaluation) -> str:
    """A readable table of a ``calibproj.evaluation.independent.Evaluation``."""
    header = f"{'camera':<16}{'mean px':>10}{'std px':>10}{'n':>8}"
    lines = [header, "-" * len(header)]
    for name, camera in evaluation.cameras.items():
        if camera.mean_px is None:
            lines.append(f"{name:<16}FAILED: {camera.failure}")
        else:
            lines.append(f"{name:<16}{camera.mean_px:10.3f}{camera.std_px:10.3f}{camera.n:8d}")
    lines.append("-" * len(header))
    overall = evaluation.mean_px
    lines.append(f"mean over all observations: {'-' if overall is None else f'{overall:.3f} px'}")
    rates = ", ".join(f"{evaluation.success_rate(t):.0f} % under {t:g} px" for t in evaluation.thresholds_px)
    lines.append(f"success: {rates} ({len(evaluation.cameras)} cameras)")
    return "\n".join(lines)
