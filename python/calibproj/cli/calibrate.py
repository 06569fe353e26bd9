"""Calibrate the cameras: register every camera and refine, then write the results.

From the camera videos of a projection (sync, frame picking, marker detection, tracks):
    calibproj calibrate VIDEOS_DIR --sequence sequence.json --intrinsics INTRINSICS_DIR --out RESULTS_DIR
From tracks (e.g. of `calibproj simulate --tracks-only` or `calibproj detect`):
    calibproj calibrate --tracks tracks.json --intrinsics INTRINSICS_DIR --out RESULTS_DIR
With a short extra projection where cameras have few points (`calibproj generate --densify`):
    calibproj calibrate DENSE_VIDEOS_DIR --sequence DENSE/sequence.json --merge RESULTS_DIR ...

Writes camera_poses.json (world-to-camera poses in the floor frame: z up, floor z = 0),
metrics.json (per camera: mean and std reprojection error, inliers, view score, or why
it failed), points.ply and tracks.json (and detect_report.json from videos). The
folder is written beside RESULTS_DIR and moved into place at the end: a run that fails
or is interrupted leaves an earlier folder as it was, and an existing folder is only
replaced, whole, with --force. The intrinsics used are
copied into RESULTS_DIR/intrinsics/ (so that evaluate and the report need nothing
else), and report.html with report/*.png is written unless --no-report.

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

from calibproj.cli.options import (add_dataclass_arguments, add_detector_option_argument,
                                        add_exposure_argument, add_refine_argument, add_shared_argument,
                                        dataclass_changed_from_args, dataclass_from_args, parse_detector_options,
                                        parse_exposures)


# Ingest options that calibrate does not take: the registration has an option of that name.
INGEST_OPTIONS_NOT_HERE = ("homography_threshold_px",)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from calibproj.ingest.options import IngestOptions
    from calibproj.registration.driver import RegistrationOptions
    from calibproj.selfcal.lenses import SelfCalibrationOptions

    # What most runs need comes first; every other knob is in a group of its own.
    parser.add_argument("videos", nargs="?", metavar="VIDEOS_DIR", help="folder of camera videos (<camera>.mp4)")
    add_shared_argument(parser, "calibrate", "--sequence")
    add_shared_argument(parser, "calibrate", "--intrinsics", " (may be left out with --nominal-fov)")
    add_shared_argument(parser, "calibrate", "--out", required=True)
    add_shared_argument(parser, "calibrate", "--scale")
    add_shared_argument(parser, "calibrate", "--export")
    add_shared_argument(parser, "calibrate", "--force")
    add_shared_argument(parser, "calibrate", "--tracks", ", instead of videos")

    output = parser.add_argument_group("output and progress")
    add_shared_argument(output, "calibrate", "--json")
    output.add_argument("--no-report", action="store_true", help="do not write report.html and report/*.png")
    add_shared_argument(output, "calibrate", "--no-progress")

    more = parser.add_argument_group("more observations and lenses")
    add_shared_argument(more, "calibrate", "--merge")
    add_refine_argument(more)
    add_shared_argument(more, "calibrate", "--nominal-fov", type=float)

    videos = parser.add_argument_group("ingest of the videos (as calibproj detect)")
    videos.add_argument("--workers", type=int, default=2, help="cameras ingested at once (default 2)")
    # The ingest's own flags, as calibproj detect takes them.
    add_exposure_argument(videos, "calibrate", " (with videos)")
    add_detector_option_argument(videos, "calibrate")
    add_dataclass_arguments(parser, RegistrationOptions, "registration options")
    add_dataclass_arguments(parser, SelfCalibrationOptions, "self-calibration options (with --refine-intrinsics)")
    # --homography-threshold-px is the registration's here; the ingest keeps its default
    # (calibproj detect sets it, then calibrate --tracks).
    add_dataclass_arguments(parser, IngestOptions, "ingest options (with videos; as calibproj detect)",
                            exclude=INGEST_OPTIONS_NOT_HERE)


def run(args: argparse.Namespace) -> int:
    from calibproj.ingest.options import IngestOptions
    from calibproj.pipeline import calibrate
    from calibproj.registration.driver import RegistrationOptions
    from calibproj.selfcal.lenses import SelfCalibrationOptions

    if (args.videos is None) == (args.tracks is None):
        raise ValueError("give either VIDEOS_DIR (with --sequence) or --tracks FILE")
    if args.videos is not None and args.sequence is None:
        raise ValueError(f"{args.videos}: calibrating from videos needs --sequence sequence.json")
    exposures = parse_exposures(args.exposure)
    if exposures and args.videos is None:
        raise ValueError("--exposure applies to videos, not to --tracks")
    ingest_options = dataclass_changed_from_args(IngestOptions, args, exclude=INGEST_OPTIONS_NOT_HERE)
    detector_options = parse_detector_options(args.detector_option)
    if (ingest_options is not None or detector_options) and args.videos is None:
        raise ValueError("ingest and detector options apply to videos, not to --tracks")
    calibration = calibrate(
        args.tracks or args.videos,
        args.intrinsics,
        sequence=args.sequence,
        out=args.out,
        options=dataclass_from_args(RegistrationOptions, args),
        scale=args.scale,
        exports=[args.export] if args.export else [],
        report=not args.no_report,
        force=args.force,
        exposures=exposures,
        ingest_options=ingest_options,
        detector_options=detector_options or None,
        workers=args.workers,
        progress=not args.no_progress,
        command=getattr(args, "command_line", None),
        refine_intrinsics=args.refine_intrinsics,
        nominal_fov_deg=args.nominal_fov,
        self_calibration_options=dataclass_from_args(SelfCalibrationOptions, args),
        merge=args.merge,
    )
    return print_results(calibration, args)


def print_results(calibration, args: argparse.Namespace) -> int:
    """The per-camera table (or ``--json``), the planes, the expected error and where
    the results are; exit status 1 when a camera failed."""
    import sys

    from calibproj.cli.summary import expected_error, format_cameras, unit_words

    if args.json:
        print(calibration.summary_json())
    else:
        from calibproj.report.page import plane_text

        print(format_cameras(calibration, args.out))
        for k, plane in enumerate(calibration.planes):
            print(f"plane {k + 1} besides the floor: {plane_text(plane, calibration.unit)}")
        if (error := expected_error(args.out, calibration.unit)) is not None:
            print(error)
        print(f"results: {args.out} ({unit_words(calibration)})")
        if not args.no_report and calibration.poses:
            print(f"report: {Path(args.out) / 'report.html'}")
    if calibration.failed:
        print(f"calibproj {args.command}: {len(calibration.failed)} camera(s) failed: "
              f"{', '.join(calibration.failed)} (why: in the table above)", file=sys.stderr)
        return 1
    return 0
