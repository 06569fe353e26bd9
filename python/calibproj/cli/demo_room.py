"""The demo: a whole calibration of a simulated operating room, from nothing.

It generates a short projection sequence, renders what the six cameras of the ``demo``
room record (four far-field GoPros, one on a surgical lamp and one zoomed on the table,
1280x720, unsynchronised, at different frame rates), calibrates them from those videos
exactly as from real recordings, puts the result in metres with one measurement (the
side of a projected marker on the floor), compares it with the ground truth, and
evaluates it as the paper does (section 3.2) on independent points in the working
volume that the rendering observed (``eval_tracks.json``).
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from calibproj.formats.file_names import path_as_recorded
from calibproj.formats.output_folder import OutputFolder

logger = logging.getLogger(__name__)

DEMO_SCENE = "demo"
LIVE_SCENE = "live"
# The live demo's projection, for the virtual room's 960x540 projector: markers of 10,
# 20 and 30 cm (scale 1 for the zoomed camera, 2 and 3 for the far-field ones at
# 640x360), 16 arrays so that the zoomed camera places a few tens of points: 9.4 s.
LIVE_SEQUENCE = {"arrays": 16, "scales": (1.0, 2.0, 3.0), "marker_px": 24.0, "projector": (960, 540),
                 "code_degree": 4, "reference_frames": 8}
# Files that mark a folder the demo wrote (what --force may replace).
DEMO_SIGNATURE = ("sequence/sequence.json", "room/scene.json", "results/camera_poses.json")


@dataclass
class DemoOptions:
    """Knobs of the demo.

    Attributes:
        markers: marker family of the projected MSMs (``aruco:<DICT>`` or ``apriltag:<family>``).
        arrays: MSM arrays projected (48 gives the zoomed camera a few tens of points).
        scales: MSM scales: 1 for the zoomed camera, 3 and 6 for the far-field ones.
        model: registration model, ``coplanar`` or ``free``.
        seed: seed of the simulation (sensor noise).
        force: replace the folder of an earlier demo (the whole folder).
        live: run the room live instead (the ``live`` room: four 640x360 cameras, one
            zoomed, under a 960x540 projector): the virtual operating room
            (``calibproj.simulate.virtual_room``) films its projector's display, and
            ``calibproj capture`` plays the projection there, records the cameras' streams
            and calibrates them. Its projection is its own (``LIVE_SEQUENCE``): ``arrays``
            and ``scales`` are the rendered demo's.
    """

    markers: str = "aruco:4X4_50"
    arrays: int = 48
    scales: tuple[float, ...] = field(default=(1.0, 3.0, 6.0))
    model: str = "coplanar"
    seed: int = 0
    force: bool = False
    live: bool = False


@dataclass
class DemoResult:
    comparison: object  # calibproj.evaluation.comparison.Comparison
    evaluation: object  # calibproj.evaluation.independent.Evaluation
    calibration: object  # calibproj.formats.calibration.Calibration
    report: Path
    seconds: dict[str, float]


def run_demo(out: str | os.PathLike, options: DemoOptions | None = None, progress: bool = True,
             command: list[str] | None = None) -> DemoResult:
    """Generate, render, calibrate and compare into ``out`` (see the module docstring);
    ``command``: the command line recorded in the results' provenance (None: a Python call).

    ``out`` is written as one transaction (``calibproj.formats.output_folder``): an existing
    demo folder is only replaced, whole, with ``options.force``."""
    options = options or DemoOptions()
    folder = OutputFolder(out, force=options.force, signature=DEMO_SIGNATURE).open()
    with folder, folder.writing() as staging:
        run = _run_live if options.live else _run
        comparison, evaluation, calibration, seconds = run(staging, options, progress, command)
    logger.info("demo written to %s", folder.path)
    return DemoResult(comparison, evaluation, calibration, folder.path / "results" / "report.html", seconds)


def _run(out: Path, options: DemoOptions, progress: bool,
         command: list[str] | None) -> tuple[object, object, object, dict[str, float]]:
    from calibproj.evaluation.comparison import compare
    from calibproj.evaluation.independent import evaluate
    from calibproj.pipeline import calibrate
    from calibproj.registration.driver import RegistrationOptions
    from calibproj.report import write_report
    from calibproj.sequence import generate
    from calibproj.simulate.render import simulate_videos

    results = out / "results"
    seconds: dict[str, float] = {}
    start = time.perf_counter()
    sequence = generate(out / "sequence", markers=options.markers, arrays=options.arrays,
                        scales=tuple(options.scales), progress=progress)
    seconds["generate"] = time.perf_counter() - start
    logger.info("sequence: %d patterns (%.1f s)", len(sequence.patterns), seconds["generate"])

    start = time.perf_counter()
    simulate_videos(DEMO_SCENE, sequence, out / "room", seed=options.seed, progress=progress)
    seconds["render"] = time.perf_counter() - start
    logger.info("videos of the %s room (%.1f s)", DEMO_SCENE, seconds["render"])

    # One measurement puts the result in metres: the side of a scale-1 marker on the
    # floor, which in a real room is measured with a ruler.
    marker_side_m = marker_side_on_floor(out / "room" / "scene.json", sequence)
    start = time.perf_counter()
    calibration = calibrate(
        out / "room" / "videos", out / "room" / "intrinsics", sequence=out / "sequence" / "sequence.json",
        out=results, options=RegistrationOptions(model=options.model), scale=f"marker-size:{marker_side_m:.9f}",
        exports=["yaml", "colmap", "anipose"], progress=progress, command=command,
        report=False,  # drawn once below, with the evaluation
    )
    seconds["calibrate"] = time.perf_counter() - start
    comparison = compare(results / "camera_poses.json", out / "room" / "truth.json")
    evaluation = evaluate(results, out / "room" / "eval_tracks.json")
    evaluation.save(results, path_as_recorded(out / "room" / "eval_tracks.json", results))
    write_report(results)
    return comparison, evaluation, calibration, seconds


def _run_live(out: Path, options: DemoOptions, progress: bool,
              command: list[str] | None) -> tuple[object, object, object, dict[str, float]]:
    """The live demo: the virtual room filmed while ``capture`` projects (no evaluation
    on independent points: nothing renders them live)."""
    from calibproj.capture.session import capture
    from calibproj.evaluation.comparison import compare
    from calibproj.registration.driver import RegistrationOptions
    from calibproj.sequence import generate
    from calibproj.simulate.virtual_room import VirtualRoom, VirtualRoomOptions

    seconds: dict[str, float] = {}
    start = time.perf_counter()
    sequence = generate(out / "sequence", markers=options.markers, progress=progress, **LIVE_SEQUENCE)
    seconds["generate"] = time.perf_counter() - start
    marker_side_m = None
    with VirtualRoom(LIVE_SCENE, out / "room", VirtualRoomOptions(seed=options.seed)) as room:
        site = room.write_site(out / "site.json", out / "sequence" / "sequence.json",
                               out / "sequence" / "projection.mp4")
        marker_side_m = marker_side_on_floor(out / "room" / "scene.json", sequence)
        start = time.perf_counter()
        calibration = capture(site, out / "results", recordings=out / "recordings", progress=progress,
                              command=command, options=RegistrationOptions(model=options.model),
                              scale=f"marker-size:{marker_side_m:.9f}", exports=["yaml", "colmap", "anipose"])
        seconds["capture"] = time.perf_counter() - start
        if room.errors:
            raise RuntimeError(f"the virtual room failed: {'; '.join(room.errors)}")
    comparison = compare(out / "results" / "camera_poses.json", out / "room" / "truth.json")
    return comparison, None, calibration, seconds


def marker_side_on_floor(scene_path: Path, sequence) -> float:
    """Side (m) of a scale-1 marker projected at the centre of the floor: what a user
    measures with a ruler. The projector looks straight down in the demo room."""
    from calibproj.simulate.scene import read_scene

    projector = read_scene(scene_path).projector
    height = float(projector.position[2]) - 0.0
    return float(sequence.layout.marker_px) * height / float(projector.fx)
