"""Run the demo: generate, render a simulated operating room, calibrate, compare.

Generates a short projection sequence, renders what six cameras of a mock operating
room record (four far-field GoPros, one on a surgical lamp and one zoomed on the table,
1280x720, unsynchronised), calibrates them from those videos, puts the result in metres
from the measured side of one projected marker, and prints how close every camera came
to the ground truth, the evaluation on independent points, and where the report is. Takes a few minutes on 2 cores.

With --live, the room runs live instead (the virtual operating room: a virtual X display
as the projector's output, four cameras streaming over loopback UDP what they see of
it) and `calibproj capture` plays the projection there, records and calibrates: about
30 s.
"""

from __future__ import annotations

import argparse

from calibproj.cli.options import add_dataclass_arguments, dataclass_from_args


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from calibproj.cli.demo_room import DemoOptions

    parser.add_argument("--out", default="calibproj-demo", metavar="DIR",
                        help="folder for the sequence, the videos and the results (default: calibproj-demo)")
    parser.add_argument("--force", action="store_true",
                        help="replace the folder of an earlier demo (the whole folder)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    add_dataclass_arguments(parser, DemoOptions, "demo options", exclude=("force",))


def run(args: argparse.Namespace) -> int:
    import time

    from calibproj.cli.compare import format_table
    from calibproj.cli.evaluate import format_table as format_evaluation
    from calibproj.cli.summary import expected_error, format_cameras, unit_words
    from calibproj.cli.demo_room import DemoOptions, run_demo

    options = dataclass_from_args(DemoOptions, args)
    started = time.perf_counter()
    result = run_demo(args.out, options, progress=not args.no_progress, command=getattr(args, "command_line", None))
    total = time.perf_counter() - started
    print()
    print("Pose errors against the ground truth (after Sim(3) alignment):")
    print(format_table(result.comparison))
    if result.evaluation is not None:
        print("\nEvaluation on independent points in the working volume (paper, section 3.2):")
        print(format_evaluation(result.evaluation))
    times = ", ".join(f"{stage} {seconds:.0f} s" for stage, seconds in result.seconds.items())
    print(f"\ntime: {times}; total {total:.0f} s")
    results = result.report.parent
    print("\nThe calibration:")
    print(format_cameras(result.calibration, results))
    if (error := expected_error(results, result.calibration.unit)) is not None:
        print(error)
    print(f"results: {results} ({unit_words(result.calibration)})")
    print(f"report: {result.report}")
    return 0 if not result.comparison.missing else 1
