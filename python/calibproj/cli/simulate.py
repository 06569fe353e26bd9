"""Simulate a camera network watching the projected markers, with ground truth.

--scene is a preset (paper, or-full, easy, medium, hard, small) or a scene.json.
--seed drives every random draw, the camera angles of the paper preset included.

With --tracks-only nothing is rendered: the MSM centres of the layout (--grid,
--arrays, --scales, --marker-px) are cast on the floor and observed by every camera
that could decode the marker at one of its scales at least (shortest side at least
--min-marker-px pixels, square wholly inside the image), as undistorted pixels with
Gaussian noise (--noise) and optional gross outliers (--outliers). OUT receives
tracks.json, eval_tracks.json (an independent evaluation set in the working volume),
intrinsics/<camera>.json, truth.json and scene.json (the realised scene).

Without --tracks-only the camera videos are rendered from --sequence (made by
calibproj generate): every camera records the floor while the projector plays the
sequence, at its own frame rate, start offset and exposure, with the scene's
photometric effects (--ideal turns them off). OUT receives videos/<camera>.mp4
(H.264, quality --crf, speed --preset), intrinsics/<camera>.json, scene.json,
eval_tracks.json (evaluation points in the working volume, observed with --eval-noise)
and truth.json (poses, plane, projector, MSM centres in every image, timing); a table of
frames, sizes and the render speed is printed.

--change NAME:pan=DEG,tilt=DEG,shift=X/Y/Z,zoom=FACTOR (repeatable) changes a camera of
the scene before it is simulated: turned about the vertical (pan) or its image's
horizontal axis (tilt, positive up), its centre moved by shift metres, its focal length
multiplied by zoom. Two runs with the same --scene and --seed, one without and one with
--change, are the same room before and after a lamp camera was moved: what `calibproj
check` is for (each run's truth.json holds its own poses).

OUT is written beside itself and moved into place at the end; an existing folder is
only replaced, whole, with --force.
"""

from __future__ import annotations

import argparse

DEFAULT_GRID = "4x8"
DEFAULT_ARRAYS = 100
DEFAULT_SCALES = "1,1.4,2,3,4,6,8"
DEFAULT_MARKER_PX = 24.0
# Files that mark a folder this command wrote (what --force may replace).
SIGNATURE = ("truth.json", "scene.json")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from calibproj.simulate import geometric as defaults
    from calibproj.simulate import render

    parser.add_argument("--scene", required=True, metavar="NAME|FILE", help="preset name or scene.json")
    parser.add_argument("--sequence", metavar="FILE", help="sequence.json to render the videos from")
    parser.add_argument("--tracks-only", action="store_true", help="write tracks instead of rendering videos")
    parser.add_argument("--noise", type=float, default=defaults.DEFAULT_NOISE_PX, metavar="PX",
                        help="Gaussian noise on observations, pixels (default %(default)s)")
    parser.add_argument("--outliers", type=float, default=0.0, metavar="FRACTION",
                        help="share of MSM observations replaced by gross outliers (default %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default %(default)s)")
    parser.add_argument("--min-marker-px", type=float, default=defaults.DEFAULT_MIN_MARKER_PX, metavar="PX",
                        help="shortest marker side a camera decodes, pixels (default %(default)s)")
    parser.add_argument("--eval-points", type=int, default=defaults.DEFAULT_EVAL_POINTS, metavar="N",
                        help="evaluation points drawn uniformly in the working volume (default %(default)s)")
    parser.add_argument("--eval-points-per-camera", type=int, default=defaults.DEFAULT_EVAL_POINTS_PER_CAMERA,
                        metavar="N", help="extra evaluation points inside each camera's view (default %(default)s)")
    parser.add_argument("--eval-height", type=float, default=defaults.DEFAULT_EVAL_HEIGHT_M, metavar="M",
                        help="height of the working volume above the floor, metres (default %(default)s)")
    parser.add_argument("--grid", default=DEFAULT_GRID, metavar="ROWSxCOLS",
                        help="markers per array, tracks only (default %(default)s)")
    parser.add_argument("--arrays", type=int, default=DEFAULT_ARRAYS, help="number of arrays (default %(default)s)")
    parser.add_argument("--scales", default=DEFAULT_SCALES, help="marker scales (default %(default)s)")
    parser.add_argument("--marker-px", type=float, default=DEFAULT_MARKER_PX,
                        help="marker side at scale 1, projector pixels (default %(default)s)")
    parser.add_argument("--crf", type=int, default=render.DEFAULT_CRF, metavar="N",
                        help="videos: x264 constant-rate factor, lower is better (default %(default)s)")
    parser.add_argument("--preset", default=render.DEFAULT_PRESET,
                        help="videos: x264 preset (default %(default)s)")
    parser.add_argument("--supersample", type=int, default=1, metavar="N",
                        help="videos: N x N samples per pixel (default %(default)s: one, prefiltered)")
    parser.add_argument("--tail", type=float, default=render.DEFAULT_TAIL_S, metavar="S",
                        help="videos: seconds recorded after the sequence ends (default %(default)s)")
    parser.add_argument("--threads", type=int, default=None, metavar="N",
                        help="videos: worker threads (default one per camera)")
    parser.add_argument("--eval-noise", type=float, default=render.DEFAULT_EVAL_NOISE_PX, metavar="PX",
                        help="videos: noise of the eval_tracks.json observations, pixels (default %(default)s)")
    parser.add_argument("--ideal", action="store_true",
                        help="videos: no ambient light, noise, blur, vignetting or gamma")
    parser.add_argument("--no-progress", action="store_true", help="videos: no progress bars")
    parser.add_argument("--change", action="append", metavar="NAME:KEY=VALUE,...",
                        help="change a camera first: pan=DEG, tilt=DEG, shift=X/Y/Z (metres), zoom=FACTOR "
                             "(repeatable; see above)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory")
    parser.add_argument("--force", action="store_true", help="replace an existing output folder (the whole folder)")


def run(args: argparse.Namespace) -> int:
    if not args.tracks_only:
        return _render_videos(args)
    from calibproj.simulate.scene import load_scene

    return _simulate_tracks(_changed(load_scene(args.scene, seed=args.seed), args.change), args)


def parse_change(text: str) -> tuple[str, object]:
    """``NAME:pan=DEG,tilt=DEG,shift=X/Y/Z,zoom=FACTOR`` as (name, CameraChange)."""
    from calibproj.simulate.scene import CameraChange

    name, colon, settings = text.partition(":")
    if not colon or not name or not settings:
        raise ValueError(f"--change {text!r}: expected NAME:KEY=VALUE,... (pan, tilt, shift, zoom)")
    values: dict[str, object] = {}
    keys = {"pan": "pan_deg", "tilt": "tilt_deg", "shift": "shift_m", "zoom": "zoom"}
    for item in settings.split(","):
        key, equals, value = item.partition("=")
        if key not in keys or not equals:
            raise ValueError(f"--change {text!r}: {item!r} is not one of pan=, tilt=, shift=X/Y/Z, zoom=")
        try:
            values[keys[key]] = (tuple(float(v) for v in value.split("/")) if key == "shift" else float(value))
        except ValueError:
            raise ValueError(f"--change {text!r}: {value!r} is not a number") from None
    shift = values.get("shift_m")
    if shift is not None and len(shift) != 3:
        raise ValueError(f"--change {text!r}: shift takes three values X/Y/Z in metres")
    try:
        return name, CameraChange(**values)
    except ValueError as error:
        raise ValueError(f"--change {text!r}: {error}") from None


def _changed(scene, changes: list[str] | None):
    if not changes:
        return scene
    parsed = dict(parse_change(text) for text in changes)
    return scene.changed(parsed)


def _render_videos(args: argparse.Namespace) -> int:
    from pathlib import Path

    from calibproj.cli.main import CommandError
    from calibproj.formats.output_folder import OutputFolder
    from calibproj.simulate import render

    if not args.sequence:
        raise CommandError("rendering videos needs --sequence SEQ_DIR/sequence.json (from calibproj generate); "
                           "or use --tracks-only")
    options = render.RenderOptions(crf=args.crf, preset=args.preset, supersample=args.supersample,
                                   tail_s=args.tail, threads=args.threads, eval_noise_px=args.eval_noise,
                                   photometric=render.IDEAL_PHOTOMETRIC if args.ideal else None)
    # The scene goes by name or path so that errors name the file (changed: loaded first).
    scene = args.scene
    if args.change:
        from calibproj.simulate.scene import load_scene

        scene = _changed(load_scene(args.scene, seed=args.seed), args.change)
    with OutputFolder(args.out, force=args.force, signature=SIGNATURE) as folder, folder.writing() as staging:
        simulation = render.simulate_videos(scene, Path(args.sequence), staging, seed=args.seed,
                                            options=options, progress=not args.no_progress)
    print(_video_summary(simulation, args.out))
    return 0


def _video_summary(simulation, out: str) -> str:
    lines = [f"{'camera':<16}{'resolution':>12}{'fps':>8}{'frames':>8}{'MB':>9}"]
    for name, video in simulation.videos.items():
        width, height = video.resolution
        lines.append(f"{name:<16}{f'{width}x{height}':>12}{video.fps:>8.2f}{video.frame_count:>8}"
                     f"{video.size_bytes / 1e6:>9.1f}")
    lines.append(f"{simulation.frame_count} frames, {simulation.size_bytes / 1e6:.1f} MB in "
                 f"{simulation.elapsed_s:.1f} s ({simulation.frames_per_second:.1f} frames/s); "
                 f"written to {out}")
    return "\n".join(lines)


def _simulate_tracks(scene, args: argparse.Namespace) -> int:
    from calibproj.cli.main import CommandError
    from calibproj.formats.output_folder import OutputFolder
    from calibproj.simulate.geometric import simulate_tracks

    if args.sequence:
        raise CommandError(
            "--tracks-only takes the marker layout from --grid, --arrays, --scales and --marker-px, "
            "not from --sequence"
        )
    layout = _layout(scene, args)
    with OutputFolder(args.out, force=args.force, signature=SIGNATURE) as folder, folder.writing() as staging:
        simulation = simulate_tracks(
            scene, staging,
            noise_px=args.noise, seed=args.seed, outlier_fraction=args.outliers, min_marker_px=args.min_marker_px,
            layout=layout, eval_points=args.eval_points,
            eval_points_per_camera=args.eval_points_per_camera, eval_height_m=args.eval_height,
        )
    print(_summary(simulation, args.out))
    return 0


def _layout(scene, args: argparse.Namespace):
    from calibproj.sequence.layout import MsmLayout

    try:
        rows, cols = (int(v) for v in args.grid.lower().split("x"))
        scales = tuple(float(v) for v in args.scales.split(","))
    except ValueError:
        raise ValueError(
            f"--grid must look like 4x8 and --scales like 1,2,4; got {args.grid!r} and {args.scales!r}"
        ) from None
    return MsmLayout(projector=scene.projector.resolution, grid=(rows, cols), arrays=args.arrays,
                     scales=scales, marker_px=args.marker_px)


def _summary(simulation, out: str) -> str:
    tracks, eval_tracks = simulation.tracks, simulation.eval_tracks
    msm_counts, eval_counts = tracks.counts_per_camera(), eval_tracks.counts_per_camera()
    lines = [f"{'camera':<16}{'MSM centres':>12}{'eval points':>12}"]
    for name in tracks.camera_names:
        lines.append(f"{name:<16}{msm_counts[name]:>12}{eval_counts[name]:>12}")
    lines.append(f"{len(tracks)} observations of {tracks.num_points} MSM centres, "
                 f"{len(eval_tracks)} of {eval_tracks.num_points} evaluation points; written to {out}")
    return "\n".join(lines)
