"""Run the room: record every camera while the projector plays the projection, then
calibrate from what arrived.

    calibproj capture SITE.json --out RESULTS_DIR
    calibproj capture SITE.json --check RESULTS_DIR --sequence CHECK/sequence.json --out REPAIRED_DIR

The site file names the room once (README, "Running a room"): each camera's source
(rtsp://, http://, udp://, a device such as /dev/video0 with "format": "v4l2", or a
file), its intrinsics file, the projector's display and screen, the projection. Every
camera is opened and ingested live (synchronised and detected as its frames arrive)
and recorded unchanged; once every camera delivers frames, the projection plays full
screen on the projector; the poses are written seconds after it ends.

RESULTS_DIR gets what `calibproj calibrate` writes, plus recordings/ (each camera's
video, as its source sent it, and capture.json: what each camera delivered and when
the projector showed each frame). A camera that cannot be opened, stalls or drops out
is reported by name and the others are calibrated. If the run fails or is interrupted
(Ctrl-C, SIGTERM), no results folder is written and the recordings stay in the
recordings folder (RESULTS_DIR-recordings-<time> unless --recordings), which the
error names: `calibproj calibrate` can calibrate them later.

With --check RESULTS_DIR, the projection is the check projection of `calibproj generate
--check RESULTS_DIR` (--sequence), the cameras' frames are read with the stored
intrinsics, and the stored calibration is checked and repaired as `calibproj check`
does (its table, its exit statuses 0, 3, 4).

Exit status: 0 every camera calibrated; 1 a camera failed (the table says why) or the
projector could not play; 2 a bad site file or option; 130 interrupted.
"""

from __future__ import annotations

import argparse

from calibproj.cli.options import (add_dataclass_arguments, add_refine_argument, add_shared_argument,
                                        dataclass_from_args)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from calibproj.registration.driver import RegistrationOptions
    from calibproj.selfcal.lenses import SelfCalibrationOptions

    parser.add_argument("site", metavar="SITE", help="the site file (calibproj.site/1: cameras, projector, projection)")
    for name in ("--out", "--force", "--recordings", "--check", "--sequence", "--projection", "--scale", "--export"):
        add_shared_argument(parser, "capture", name)
    add_refine_argument(parser)
    output = parser.add_argument_group("output and progress")
    add_shared_argument(output, "capture", "--json")
    output.add_argument("--no-report", action="store_true", help="do not write report.html and report/*.png")
    add_shared_argument(output, "capture", "--no-progress")
    add_dataclass_arguments(parser, RegistrationOptions, "registration options")
    add_dataclass_arguments(parser, SelfCalibrationOptions, "self-calibration options (with --refine-intrinsics)")


def run(args: argparse.Namespace) -> int:
    from calibproj.capture.session import capture
    from calibproj.cli.calibrate import print_results
    from calibproj.registration.driver import RegistrationOptions
    from calibproj.selfcal.lenses import SelfCalibrationOptions

    if args.check is not None:
        return run_check(args)
    if args.out is None:
        raise ValueError("--out DIR is needed (the results folder) unless --check")
    if args.projection is not None and args.sequence is None:
        raise ValueError("--projection goes with --sequence (the site file names its own projection)")
    calibration = capture(
        args.site,
        args.out,
        force=args.force,
        recordings=args.recordings,
        progress=not args.no_progress,
        command=getattr(args, "command_line", None),
        options=dataclass_from_args(RegistrationOptions, args),
        scale=args.scale,
        exports=[args.export] if args.export else [],
        report=not args.no_report,
        refine_intrinsics=args.refine_intrinsics,
        self_calibration_options=dataclass_from_args(SelfCalibrationOptions, args),
        sequence=args.sequence,
        projection=args.projection,
    )
    return print_results(calibration, args)


def run_check(args: argparse.Namespace) -> int:
    """``--check RESULTS``: the check projection played and recorded, the stored
    calibration checked (and repaired into --out), printed as calibproj check prints."""
    from calibproj.capture.session import capture_check
    from calibproj.check.repair import UntrustedReference
    from calibproj.cli.check import print_check

    if args.sequence is None:
        raise ValueError("--check needs --sequence (the check projection's sequence.json)")
    if args.scale or args.refine_intrinsics:
        raise ValueError("--scale and --refine-intrinsics are for calibrating, not with --check")
    try:
        result = capture_check(args.site, args.check, args.out, sequence=args.sequence, projection=args.projection,
                               force=args.force, recordings=args.recordings, progress=not args.no_progress,
                               command=getattr(args, "command_line", None),
                               exports=[args.export] if args.export else [], report=not args.no_report)
        untrusted = None
    except UntrustedReference as error:
        result, untrusted = error.result, error
    return print_check(result, untrusted, args)
