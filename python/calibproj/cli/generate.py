"""Write the projection sequence: a video for the projector and sequence.json.

The video shows white and black reference frames, a start light code, every MSM
array at every scale (array-major), an end light code and reference frames again.
sequence.json holds everything needed to decode a recording of it later.

Defaults follow the paper: 100 arrays of 4x8 ArUco markers (3200 points), scales
1,1.4,2,3,4,6,8, white markers on black, 1920x1080 at 30 fps, 3 frames per pattern
(so that a 25 fps camera sees every pattern in at least one clean frame).

SEQ_DIR is written beside itself and moved into place at the end; an existing folder
is only replaced, whole, with --force.

Densification (--densify RESULTS): a short extra projection (at most --densify-seconds,
codes included) that fills the view of each weak camera, or camera with few points,
with MSMs sized for it, planned from the calibration in RESULTS. Its sequence keeps the
arrays of the sequence RESULTS came from (--sequence; default: the one its
provenance.json names) and shows only the new ones. Record it with the cameras as
they are, then: calibproj calibrate DENSE_VIDEOS --sequence SEQ_DIR/sequence.json
--merge RESULTS ... The marker family, projector, frame rates and codes are the
sequence's; the layout options above do not apply.

Check (--check RESULTS): the projection `calibproj check` tests a calibration with, at
most --check-seconds (8 s) long, with shorter light codes (15 bits) and reference
blocks: some of the arrays RESULTS were calibrated from, chosen so that every camera,
the zoomed one included, sees --check-points of its calibrated points again. The
sequences default to the one RESULTS' provenance names and, for a merged calibration
(or one `calibproj check --out` repaired), the ones behind it; --sequence (repeatable)
gives them. Then: calibproj check RESULTS CHECK_VIDEOS --sequence
SEQ_DIR/sequence.json [--out NEW_RESULTS].
"""

from __future__ import annotations

import argparse
import json

from calibproj.cli.main import CommandError
from calibproj.sequence.check_sequence import CheckSequenceOptions
from calibproj.sequence.densify import DensifyOptions


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, metavar="SEQ_DIR", help="output folder")
    parser.add_argument("--force", action="store_true", help="replace an existing output folder (the whole folder)")
    parser.add_argument("--markers", default="aruco:4X4_50",
                        help="marker family: aruco:<DICT> or apriltag:<family> (default: %(default)s)")
    parser.add_argument("--grid", default="4x8", help="markers per array, ROWSxCOLS (default: %(default)s)")
    parser.add_argument("--arrays", type=int, default=100, help="number of arrays (default: %(default)s)")
    parser.add_argument("--scales", default="1,1.4,2,3,4,6,8", help="scale factors (default: %(default)s)")
    parser.add_argument("--marker-px", type=float, default=24.0,
                        help="marker side at scale 1 in projector pixels (default: %(default)s)")
    parser.add_argument("--margin-px", type=float, default=None,
                        help="image edge to outermost centres (default: keep the largest scale inside)")
    parser.add_argument("--projector", default="1920x1080", help="projector resolution WxH (default: %(default)s)")
    parser.add_argument("--fps", type=float, default=30.0, help="projector frame rate (default: %(default)s)")
    parser.add_argument("--frames-per-pattern", type=int, default=None,
                        help="frames per pattern (default: derived from --min-camera-fps)")
    parser.add_argument("--min-camera-fps", type=float, default=25.0,
                        help="slowest camera that must see every pattern in one clean frame (default: %(default)s)")
    parser.add_argument("--inverted", action=argparse.BooleanOptionalAction, default=True,
                        help="white markers on black (default: on)")
    parser.add_argument("--min-gap-modules", type=float, default=0.5,
                        help="smallest gap between markers of one pattern, in modules (default: %(default)s)")
    parser.add_argument("--omit-conflicting", action="store_true",
                        help="leave out markers that overlap or leave the image at some scale, instead of failing")
    parser.add_argument("--code-degree", type=int, default=5,
                        help="light codes are m-sequences of 2^N-1 bits (default: %(default)s)")
    parser.add_argument("--code-frames-per-bit", type=int, default=None,
                        help="frames per light-code bit (default: as frames per pattern)")
    parser.add_argument("--reference-frames", type=int, default=15,
                        help="frames of each white or black block around the codes (default: %(default)s)")
    parser.add_argument("--png", action="store_true", help="also write every pattern as a PNG")
    parser.add_argument("--no-video", dest="video", action="store_false", help="write sequence.json only")
    parser.add_argument("--crf", type=int, default=None,
                        help="x264 quality, lower is better (default: 4; 0 is lossless, for players with "
                             "H.264's High 4:4:4 Predictive profile)")
    parser.add_argument("--preset", default=None, help="x264 preset (default: veryfast)")
    parser.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")
    parser.add_argument("--json", action="store_true", help="print a JSON summary")
    densify = parser.add_argument_group("densification (see above)")
    densify.add_argument("--densify", metavar="RESULTS",
                         help="plan an extra projection for the weak cameras of this results folder")
    densify.add_argument("--sequence", metavar="FILE", action="append",
                         help="with --densify or --check: the sequence.json RESULTS were calibrated from "
                              "(default: the one its provenance.json names); repeatable with --check")
    densify.add_argument("--densify-seconds", type=float, default=DensifyOptions.max_seconds,
                         help="longest extra projection, codes included (default: %(default)s)")
    densify.add_argument("--densify-cameras", metavar="NAMES",
                         help="comma-separated cameras to densify for (default: the weak ones and those with "
                              "fewer than --densify-min-points inliers)")
    densify.add_argument("--densify-min-points", type=int, default=DensifyOptions.min_points,
                         help="inliers below which a camera is densified for (default: %(default)s)")
    check = parser.add_argument_group("check projection (see above)")
    check.add_argument("--check", metavar="RESULTS",
                       help="plan the short projection `calibproj check` tests RESULTS with")
    check.add_argument("--check-seconds", type=float, default=CheckSequenceOptions.max_seconds,
                       help="longest check projection, codes included (default: %(default)s)")
    check.add_argument("--check-points", type=int, default=CheckSequenceOptions.points_per_camera,
                       help="calibrated points each camera should see again (default: %(default)s)")
    densify.add_argument("--densify-gap-modules", type=float, default=DensifyOptions.min_gap_modules,
                         help="smallest gap between two extra markers, in modules of the largest: room for "
                              "oblique cameras to see them apart (default: %(default)s)")


def run(args: argparse.Namespace) -> int:
    if args.densify is not None and args.check is not None:
        raise CommandError("--densify and --check plan different projections: give one")
    if args.densify is not None:
        return _run_densify(args)
    if args.check is not None:
        return _run_check(args)
    if args.sequence is not None:
        raise CommandError("--sequence applies to --densify and --check")
    from calibproj.formats.output_folder import OutputFolder
    from calibproj.sequence import SequenceOptions, generate
    from calibproj.sequence.builder import SEQUENCE_FILE
    from calibproj.sequence.video import DEFAULT_CRF, DEFAULT_PRESET

    options = SequenceOptions(
        markers=args.markers, grid=_pair(args.grid, "--grid", "4x8"), arrays=args.arrays,
        scales=_scales(args.scales), marker_px=args.marker_px, margin_px=args.margin_px,
        projector=_pair(args.projector, "--projector", "1920x1080"), fps=args.fps,
        frames_per_pattern=args.frames_per_pattern, min_camera_fps=args.min_camera_fps, inverted=args.inverted,
        min_gap_modules=args.min_gap_modules, omit_conflicting=args.omit_conflicting,
        code_degree=args.code_degree, code_frames_per_bit=args.code_frames_per_bit,
        reference_frames=args.reference_frames,
    )
    with OutputFolder(args.out, force=args.force, signature=[SEQUENCE_FILE]) as folder, \
            folder.writing() as staging:
        sequence = generate(staging, options, video=args.video, png=args.png,
                            crf=DEFAULT_CRF if args.crf is None else args.crf,
                            preset=args.preset or DEFAULT_PRESET, progress=args.progress and not args.json)
    summary = {
        "sequence": f"{args.out}/sequence.json",
        "video": f"{args.out}/projection.mp4" if args.video else None,
        "markers": sequence.markers.spec,
        "frames": sequence.frame_count,
        "duration_s": round(sequence.duration_s, 3),
        "patterns": len(sequence.patterns),
        "points": sequence.point_count,
        "omitted": sum(len(p.omitted) for p in sequence.patterns),
    }
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"{summary['sequence']}: {sequence.markers.spec}, {summary['patterns']} patterns, "
              f"{summary['points']} points, {summary['frames']} frames ({summary['duration_s']:.1f} s)")
    return 0


def _pair(text: str, option: str, example: str) -> tuple[int, int]:
    try:
        first, second = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise CommandError(f"{option} must look like {example}, got {text!r}") from None
    return first, second


def _scales(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise CommandError(f"--scales must look like 1,1.4,2, got {text!r}") from None


def _run_densify(args: argparse.Namespace) -> int:
    from pathlib import Path

    from calibproj.sequence import Sequence
    from calibproj.sequence.densify import densify

    results = _results_folder(args.densify)
    cameras = tuple(n.strip() for n in args.densify_cameras.split(",") if n.strip()) if args.densify_cameras else None
    options = DensifyOptions(max_seconds=args.densify_seconds, cameras=cameras, min_points=args.densify_min_points,
                             min_gap_modules=args.densify_gap_modules)
    if args.sequence and len(args.sequence) > 1:
        raise CommandError("--densify takes one --sequence: the one RESULTS were calibrated from")
    sequence_path = Path(args.sequence[0]) if args.sequence else _calibrated_sequence(results)
    dense, plans = densify(results, Sequence.load(sequence_path), options)
    summary = {"sequence": None, "video": None, "extra_seconds": 0.0, "cameras": {}}
    if dense is not None:
        _write_planned(args, dense)
        summary.update(sequence=f"{args.out}/sequence.json", video=f"{args.out}/projection.mp4" if args.video else None,
                       extra_seconds=round(dense.duration_s, 3))
        for plan in plans:
            low, high = plan.footprint.camera_px_per_projector_px
            summary["cameras"][plan.footprint.camera] = {
                "arrays": len(plan.centres), "centres": int(sum(len(c) for c in plan.centres)),
                "points_before": plan.footprint.points, "marker_sides_projector_px": list(plan.sides_px),
                "marker_sides_camera_px": [round(plan.sides_px[0] * low, 1), round(plan.sides_px[-1] * high, 1)]}
    if args.json:
        print(json.dumps(summary))
    elif dense is None:
        print(f"{results}: no camera needs densification (none is weak or has fewer than "
              f"{options.min_points} inliers); nothing written")
    else:
        for name, entry in summary["cameras"].items():
            low, high = entry["marker_sides_camera_px"]
            print(f"{name}: {entry['centres']} new centres in {entry['arrays']} arrays (it had "
                  f"{entry['points_before']} points), markers of {low:.0f}-{high:.0f} px in its image")
        print(f"{summary['sequence']}: extra projection of {dense.duration_s:.1f} s; record it, then calibrate "
              f"with --sequence {summary['sequence']} --merge {results}")
    return 0


def _run_check(args: argparse.Namespace) -> int:
    from pathlib import Path

    from calibproj.sequence import Sequence
    from calibproj.sequence.check_sequence import plan_check

    results = _results_folder(args.check)
    paths = [Path(p) for p in args.sequence] if args.sequence else _calibrated_sequences(results)
    options = CheckSequenceOptions(max_seconds=args.check_seconds, points_per_camera=args.check_points)
    sequence, seen, resolution = plan_check(results, [Sequence.load(path) for path in paths], options)
    _write_planned(args, sequence)
    summary = {"sequence": f"{args.out}/sequence.json", "video": f"{args.out}/projection.mp4" if args.video else None,
               "seconds": round(sequence.duration_s, 3), "points": seen,
               "resolution_px": {name: None if sigma is None else round(sigma, 4) for name, sigma in resolution.items()}}
    if args.json:
        print(json.dumps(summary))
    else:
        for name, points in seen.items():
            sigma = resolution[name]
            resolves = "" if sigma is None else f"; a move of the working volume resolved to {sigma:.2f} px (1 sigma)"
            print(f"{name}: {points} calibrated points shown again{resolves}")
        print(f"{summary['sequence']}: check projection of {sequence.duration_s:.1f} s; record it with every camera, "
              f"then: calibproj check {results} VIDEOS --sequence {summary['sequence']}")
    return 0


def _results_folder(text: str) -> "Path":
    from pathlib import Path

    results = Path(text)
    if not results.is_dir():
        raise CommandError(f"{results}: no such results folder")
    return results


def _write_planned(args: argparse.Namespace, sequence) -> None:
    """A planned (densified or check) sequence written to --out as generate writes one."""
    from calibproj.formats.output_folder import OutputFolder
    from calibproj.sequence.builder import SEQUENCE_FILE, write_sequence
    from calibproj.sequence.video import DEFAULT_CRF, DEFAULT_PRESET

    with OutputFolder(args.out, force=args.force, signature=[SEQUENCE_FILE]) as folder, folder.writing() as staging:
        write_sequence(staging, sequence, video=args.video, png=args.png,
                       crf=DEFAULT_CRF if args.crf is None else args.crf, preset=args.preset or DEFAULT_PRESET,
                       progress=args.progress and not args.json)


def _calibrated_sequences(results, seen: set | None = None) -> list:
    """The sequences a results folder was calibrated from: its own and, when it merged an
    earlier calibration or repaired a checked one, that one's (recursively). A folder
    `calibproj check --out` wrote is planned from the calibration it repaired."""
    from pathlib import Path

    from calibproj.formats.provenance import read_provenance

    seen = set() if seen is None else seen
    seen.add(Path(results).resolve())
    inputs = (read_provenance(results) or {}).get("inputs") or {}
    earlier = [entry.get("path") for entry in (inputs.get("merged"), inputs.get("checked")) if isinstance(entry, dict)]
    earlier = [Path(p) if Path(p).is_absolute() else Path(results) / p for p in earlier if isinstance(p, str)]
    paths = [] if inputs.get("checked") else [_calibrated_sequence(results)]
    for folder in earlier:
        if folder.is_dir() and folder.resolve() not in seen:
            paths += _calibrated_sequences(folder, seen)
    if not paths:
        raise CommandError(f"{results}: its provenance names no sequence to plan from; give it with --sequence")
    return paths


def _calibrated_sequence(results) -> "Path":
    """The sequence file the results' provenance names, if it is still there unchanged."""
    import hashlib
    from pathlib import Path

    from calibproj.formats.provenance import read_provenance

    entry = ((read_provenance(results) or {}).get("inputs") or {}).get("sequence")
    if not isinstance(entry, dict) or not isinstance(entry.get("path"), str):
        raise CommandError(f"{results}: its provenance names no sequence file; give it with --sequence")
    path = Path(entry["path"])
    path = path if path.is_absolute() else results / path
    if not path.is_file():
        raise CommandError(f"{path}: the sequence {results} was calibrated from is gone; give it with --sequence")
    if "sha256" in entry and hashlib.sha256(path.read_bytes()).hexdigest() != entry["sha256"]:
        raise CommandError(f"{path}: changed since {results} was calibrated; give the original with --sequence")
    return path
