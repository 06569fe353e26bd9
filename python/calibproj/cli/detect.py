"""Synchronise camera videos with the projection sequence and detect the MSMs: tracks.json.

Every video in VIDEOS_DIR (<camera>.mp4, .mov, ...) is decoded once: the start and end
light codes of --sequence give the map from sequence time to the camera's frames
(offset, rate, exposure); the frames showing each pattern cleanly are picked; the
markers are detected (in regions of interest once the camera's projector-to-image
homography is known), undistorted with --intrinsics DIR/<camera>.json and their centres
merged over the scales.

Writes --out (tracks.json) and, next to it, its report (detect_report.json beside
tracks.json, NAME.detect_report.json beside any other NAME.json; per camera: sync offset
and rate, frames used, markers detected per scale, MSMs kept, or why the camera
failed), and prints the summary. A camera that fails is reported; the others still
give tracks. Exit status 1 when every camera failed. --out is checked (and locked
against a second run writing it) before the videos are read; an existing --out is
replaced only with --force, and never when it is the run's --sequence.
"""

from __future__ import annotations

import argparse

from calibproj.cli.options import (add_dataclass_arguments, add_detector_option_argument,
                                        add_exposure_argument, add_shared_argument, dataclass_from_args, parse_detector_options,
                                        parse_exposures)

def add_arguments(parser: argparse.ArgumentParser) -> None:
    from calibproj.ingest.videos import DEFAULT_WORKERS
    from calibproj.ingest.options import IngestOptions

    parser.add_argument("videos", metavar="VIDEOS_DIR", help="folder of camera videos (<camera>.mp4)")
    add_shared_argument(parser, "detect", "--sequence", required=True)
    add_shared_argument(parser, "detect", "--intrinsics", required=True)
    add_shared_argument(parser, "detect", "--out", required=True)
    add_shared_argument(parser, "detect", "--force")
    parser.add_argument("--workers", type=int, default=DEFAULT_WORKERS,
                        help=f"cameras processed at once (default {DEFAULT_WORKERS})")
    add_detector_option_argument(parser, "detect")
    add_exposure_argument(parser, "detect")
    add_shared_argument(parser, "detect", "--no-progress")
    add_shared_argument(parser, "detect", "--json")
    add_dataclass_arguments(parser, IngestOptions, "ingest options")


def run(args: argparse.Namespace) -> int:
    import json

    from calibproj import _core
    from calibproj.ingest import videos as ingest
    from calibproj.ingest.options import IngestOptions
    from calibproj.formats.output_folder import OutputFile

    options = dataclass_from_args(IngestOptions, args)
    detector_options, exposures = parse_detector_options(args.detector_option), parse_exposures(args.exposure)
    with OutputFile(args.out, force=args.force, inputs=[args.sequence]) as output:
        result = ingest.ingest(args.videos, args.sequence, args.intrinsics, options=options,
                               detector_options=detector_options, workers=args.workers,
                               progress=not args.no_progress, exposures=exposures)
        with output.writing() as out:
            result.tracks.write(out)
            result.write_report(_core.formats.detect_report_path(out))
    report = result.report()
    print(json.dumps(report, indent=1) if args.json else format_report(report))
    return 0 if len(result.failed) < len(result.cameras) else 1


def drift_note(camera: dict) -> str:
    """How far the centres were moved for their scales' drift, when they were."""
    drift = camera.get("scale_drift") or {}
    if not drift.get("corrected"):
        return ""
    return f" (moved {drift['rms_shift_px']:.3f} px rms for their scales' drift)"


def format_report(report: dict) -> str:
    """Per camera: sync, frames, markers per scale, MSMs kept (or the error)."""
    lines = []
    for name, camera in report["cameras"].items():
        if camera["status"] != "ok":
            lines.append(f"{name}: FAILED: {camera['error']}")
            continue
        sync, frames = camera["sync"], camera["frames"]
        lines.append(
            f"{name}: offset {sync['offset_s']:.4f} s ({sync['offset_frames']:.3f} +- "
            f"{sync['offset_uncertainty_frames']:.3f} frames), {sync['camera_fps']:.4f} fps "
            f"({sync['drift_ppm']:+.0f} ppm), codes {sync['start_correlation']:.3f}/{sync['end_correlation']:.3f}; "
            f"frames {frames['decoded']} decoded ({frames['dropped']} dropped, {frames['duplicated']} duplicated), "
            f"{frames['detected']} detected; {camera['msms_kept']} MSMs kept{drift_note(camera)}")
        per_scale = ", ".join(f"{s['scale']:g}: {s['detected']}/{s['searched']}" for s in camera["scales"])
        lines.append(f"    markers found/searched per scale: {per_scale}")
    return "\n".join(lines)
