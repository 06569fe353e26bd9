"""Intrinsics from a calibration board seen in a video or images (OpenCV calibration).

SOURCE is a video (every --step-th frame is looked at), a folder of images or one
image. --board is `chessboard:COLSxROWS:SQUARE_M` (inner corners) or
`charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT` (squares; e.g. charuco:5x7:0.04:0.03:4X4_50).
Blurred views are left out and the views covering the image best are kept
(--max-views); the camera matrix and distortion are written as calibproj's intrinsics
JSON (the camera is named after OUT's file stem), with how they were measured
(`board_calibration`: each parameter's 1-sigma, the RMS error of every view, and every
image left out with why), and with --plot a PNG of where the corners lie in the image.
"""

from __future__ import annotations

import argparse

from calibproj.cli.options import add_dataclass_arguments


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from calibproj.board.fit import BoardOptions

    parser.add_argument("source", metavar="SOURCE", help="video, folder of images, or one image of the board")
    parser.add_argument("--board", required=True, metavar="SPEC",
                        help="chessboard:COLSxROWS:SQUARE_M or charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT")
    parser.add_argument("--out", required=True, metavar="FILE", help="intrinsics JSON to write (<camera>.json)")
    parser.add_argument("--plot", metavar="PNG", help="also draw the corners' coverage and the views' errors here")
    parser.add_argument("--force", action="store_true", help="replace an existing --out")
    parser.add_argument("--json", action="store_true", help="print the result as JSON (for programs)")
    add_dataclass_arguments(parser, BoardOptions, "board calibration options")


def run(args: argparse.Namespace) -> int:
    import json
    from contextlib import nullcontext
    from pathlib import Path

    from calibproj.board import BoardOptions, BoardSpec, calibrate_with_board
    from calibproj.cli.options import dataclass_from_args
    from calibproj.formats.intrinsics import write_intrinsics
    from calibproj.formats.jsonio import atomic_write_bytes
    from calibproj.formats.output_folder import OutputFile

    board = BoardSpec.parse(args.board)  # before reading the video: a typo is one line at once
    out = Path(args.out)
    plot = Path(args.plot) if args.plot else None
    if plot is not None and plot.resolve() == out.resolve():
        raise ValueError(f"{plot}: --plot and --out are the same file; give the picture its own path")
    # Both outputs checked and locked before the calibration; the picture drawn before
    # anything is written, so a failure leaves both as they were.
    with OutputFile(out, force=args.force) as out_file, \
            (OutputFile(plot, force=True) if plot else nullcontext()) as plot_file:
        result = calibrate_with_board(args.source, board, name=out.stem,
                                      options=dataclass_from_args(BoardOptions, args))
        if plot is not None:
            from calibproj.board.figure import coverage_figure

            picture = coverage_figure(result)
            with plot_file.writing():
                atomic_write_bytes(plot, picture)
        with out_file.writing():
            write_intrinsics(out, result.intrinsics, {"board_calibration": result.measurement()})
    if args.json:
        print(json.dumps(result.summary(), indent=1))
    else:
        print(format_result(result))
        print(f"intrinsics written to {out}")
    return 0


def format_result(result) -> str:
    K, sigma = result.intrinsics.K, result.sigmas
    dist = ", ".join(f"{name} {value:.5f} +- {sigma.get(name, float('nan')):.5f}"
                     for name, value in zip(("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"), result.intrinsics.dist))
    worst = max(zip(result.view_rms_px, (v.label for v in result.views)))
    return "\n".join([
        f"board {result.board}: found in {result.found} of {result.seen} images, {len(result.views)} views used",
        f"fx {K[0, 0]:.2f} +- {sigma['fx']:.2f}  fy {K[1, 1]:.2f} +- {sigma['fy']:.2f}  "
        f"cx {K[0, 2]:.2f} +- {sigma['cx']:.2f}  cy {K[1, 2]:.2f} +- {sigma['cy']:.2f} px",
        f"distortion: {dist}",
        f"RMS reprojection error {result.rms_px:.3f} px (worst view {worst[1]}: {worst[0]:.3f} px)",
        *left_out_lines(result.left_out),
    ])


# Labels named per reason at most; the intrinsics file lists them all.
LISTED_LABELS = 8


def left_out_lines(left_out: dict[str, str]) -> list[str]:
    """The images not used, grouped by why (the reason's words before its details)."""
    groups: dict[str, list[str]] = {}
    for label, reason in left_out.items():
        groups.setdefault(reason.split(" (")[0], []).append(label)
    lines = []
    for reason, labels in groups.items():
        named = ", ".join(labels[:LISTED_LABELS])
        more = f" and {len(labels) - LISTED_LABELS} more" if len(labels) > LISTED_LABELS else ""
        lines.append(f"left out, {reason}: {named}{more}")
    return lines
