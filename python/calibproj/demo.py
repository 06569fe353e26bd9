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
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

logger = logging.getLogger(__name__)

DEMO_SCENE = "demo"


@dataclass
class DemoOptions:
    """Knobs of the demo.

    Attributes:
        markers: marker family of the projected MSMs (``aruco:<DICT>`` or ``apriltag:<family>``).
        arrays: MSM arrays projected (48 gives the zoomed camera a few tens of points).
        scales: MSM scales: 1 for the zoomed camera, 3 and 6 for the far-field ones.
        model: registration model, ``coplanar`` or ``free``.
        seed: seed of the simulation (sensor noise).
        force: replace the results of an earlier demo in the output folder.
    """

    markers: str = "aruco:4X4_50"
    arrays: int = 48
    scales: tuple[float, ...] = field(default=(1.0, 3.0, 6.0))
    model: str = "coplanar"
    seed: int = 0
    force: bool = False


@dataclass
class DemoResult:
    comparison: object  # calibproj.comparison.Comparison
    evaluation: object  # calibproj.evaluation.Evaluation
    calibration: object  # calibproj.calibration.Calibration
    report: Path
    seconds: dict[str, float]


def run_demo(out: str | os.PathLike, options: DemoOptions | None = None, progress: bool = True) -> DemoResult:
    """Generate, render, calibrate and compare into ``out`` (see the module docstring)."""
    from calibproj.comparison import compare
    from calibproj.evaluation import evaluate
    from calibproj.sequence import generate
    from calibproj.pipeline import check_output_folder
    from calibproj.pipeline import calibrate
    from calibproj.registration import RegistrationOptions
    from calibproj.simulate.render import simulate_videos

    options = options or DemoOptions()
    out = Path(out)
    results = out / "results"
    check_output_folder(results, options.force)
    if options.force and out.exists():
        for part in ("sequence", "room", "results"):
            shutil.rmtree(out / part, ignore_errors=True)
    seconds: dict[str, float] = {}

    start = time.perf_counter()
    sequence = generate(out / "sequence", markers=options.markers, arrays=options.arrays,
                        scales=tuple(options.scales), progress=progress)
    seconds["generate"] = time.perf_counter() - start
    logger.info("sequence: %d patterns in %s (%.1f s)", len(sequence.patterns), out / "sequence", seconds["generate"])

    start = time.perf_counter()
    simulate_videos(DEMO_SCENE, sequence, out / "room", seed=options.seed, progress=progress)
    seconds["render"] = time.perf_counter() - start
    logger.info("videos of the %s room in %s (%.1f s)", DEMO_SCENE, out / "room", seconds["render"])

    # One measurement puts the result in metres: the side of a scale-1 marker on the
    # floor, which in a real room is measured with a ruler.
    marker_side_m = marker_side_on_floor(out / "room" / "scene.json", sequence)
    start = time.perf_counter()
    calibration = calibrate(
        out / "room" / "videos", out / "room" / "intrinsics", sequence=out / "sequence" / "sequence.json",
        out=results, options=RegistrationOptions(model=options.model), scale=f"marker-size:{marker_side_m:.9f}",
        exports=["yaml", "colmap", "anipose"], force=options.force, progress=progress,
    )
    seconds["calibrate"] = time.perf_counter() - start
    comparison = compare(results / "camera_poses.json", out / "room" / "truth.json")
    evaluation = evaluate(results, out / "room" / "eval_tracks.json")
    return DemoResult(comparison, evaluation, calibration, results / "report.html", seconds)


def marker_side_on_floor(scene_path: Path, sequence) -> float:
    """Side (m) of a scale-1 marker projected at the centre of the floor: what a user
    measures with a ruler. The projector looks straight down in the demo room."""
    from calibproj.simulate.scene import read_scene

    projector = read_scene(scene_path).projector
    height = float(projector.position[2]) - 0.0
    return float(sequence.layout.marker_px) * height / float(projector.fx)
