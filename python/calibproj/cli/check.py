"""Check a calibration with a short projection; with --out, repair the cameras that changed.

    calibproj generate --check RESULTS --out CHECK/          # at most 8 s of projection
    calibproj check RESULTS CHECK_VIDEOS_DIR --sequence CHECK/sequence.json [--out NEW_RESULTS]

Each camera of RESULTS is tested on its new observations of the calibrated points
(the check projection shows some of the calibrated arrays again): its pose, its focal
length and both are fitted with the points held, and the change from the same fit to
its calibration's observations is judged twice, by a chi-square with both fits'
covariance (99.9 %) and by how far it moves the working volume (over the calibrated
points, floor to 2 m in a metric calibration) in the camera's image (--tolerance-px,
default 0.5 px). Statuses:

    unchanged   no change both significant and above the tolerance
    moved       its pose changed (the new pose is given)
    rezoomed    its focal length changed (a PTZ camera's zoom), perhaps its pose too
    not seen    no calibrated point seen (covered, off, turned away): keeps its stored pose
    unknown     too few observations to test (said with how many)

If the cameras that agree with RESULTS are not a clear majority of those tested, the
floor, the projector or most cameras changed: nothing is repaired, run a full
calibration. With --out, the moved and re-zoomed cameras get their new poses (and focal
lengths) and a complete results folder is written, as calibrate writes one, with
check.json (each camera's status, change with its sigma, residuals before and after).

Exit status: 0 every camera confirmed (or repaired, with --out); 3 some camera changed
(without --out), or was not seen or could not be tested (fewer than two tested: nothing
repaired); 4 the cameras that agree with RESULTS are not a clear majority (run a full
calibration); 1 and 2 as for every command.
"""

from __future__ import annotations

import argparse

from calibproj.cli.options import add_dataclass_arguments, add_shared_argument, dataclass_from_args

def add_arguments(parser: argparse.ArgumentParser) -> None:
    from calibproj.check.repair import CheckOptions

    parser.add_argument("results", metavar="RESULTS", help="results folder of calibproj calibrate")
    parser.add_argument("videos", nargs="?", metavar="VIDEOS_DIR", help="folder of the check projection's videos")
    add_shared_argument(parser, "check", "--tracks", extra_help=", instead of videos")
    parser.add_argument("--sequence", metavar="FILE", help="sequence.json of the check projection (with videos)")
    add_shared_argument(parser, "check", "--out")
    add_shared_argument(parser, "check", "--force")
    add_shared_argument(parser, "check", "--export")
    parser.add_argument("--no-report", action="store_true", help="with --out: no report.html")
    add_shared_argument(parser, "check", "--json")
    parser.add_argument("--workers", type=int, default=2, help="cameras ingested at once (default 2)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    add_dataclass_arguments(parser, CheckOptions, "check options")


def run(args: argparse.Namespace) -> int:
    from calibproj.check.repair import CheckOptions, UntrustedReference, check

    if (args.videos is None) == (args.tracks is None):
        raise ValueError("give either VIDEOS_DIR (with --sequence) or --tracks FILE")
    if args.videos is not None and args.sequence is None:
        raise ValueError(f"{args.videos}: checking from videos needs --sequence (the check projection's sequence.json)")
    try:
        result = check(args.results, args.tracks or args.videos, sequence=args.sequence, out=args.out,
                       options=dataclass_from_args(CheckOptions, args), force=args.force,
                       exports=[args.export] if args.export else [], report=not args.no_report,
                       workers=args.workers, progress=not args.no_progress,
                       command=getattr(args, "command_line", None))
        untrusted = None
    except UntrustedReference as error:
        result, untrusted = error.result, error
    return print_check(result, untrusted, args)


def print_check(result, untrusted, args: argparse.Namespace) -> int:
    """The verdicts (or ``--json``), the conclusion and where the repair is; the exit
    status of the check."""
    if args.json:
        print(result.json(), end="")
    else:
        print(result.table())
        print(str(untrusted) if untrusted else result.message)
        if args.out and not untrusted:
            print(f"repaired results in {args.out}")
    return result.exit_status(repaired=bool(args.out) and untrusted is None)
