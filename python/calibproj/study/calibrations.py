"""The calibration part of the marker study: one room rendered under one condition with
one marker family's sequence, calibrated from its videos, compared with the truth."""

from __future__ import annotations

import math
import tempfile
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

CONDITIONS = ("clean", "room-light", "rolling-15ms")


@dataclass(frozen=True)
class CalibrationCondition:
    """One calibration of the study.

    Attributes:
        family: marker family spec.
        condition: ``clean``, ``room-light`` (ambient 0.4, contrast 0.3) or
            ``rolling-15ms`` (every camera's rows read out over 15 ms).
        room: scene preset.
        arrays: MSM arrays projected.
        seed: rendering seed.
    """

    family: str
    condition: str
    room: str
    arrays: int
    seed: int = 0


def run_calibration(task: CalibrationCondition) -> dict[str, Any]:
    """Registered cameras, rotation and translation RMSE against the truth (over the
    cameras not reported weak), evaluation error on independent points and the
    ingest's detection time per frame, in a dict with the task's fields."""
    from calibproj.evaluation.comparison import compare
    from calibproj.evaluation.independent import EvaluationOptions, evaluate
    from calibproj.pipeline import calibrate
    from calibproj.sequence import generate
    from calibproj.simulate.render import simulate_videos
    from calibproj.simulate.scene import load_scene

    row: dict[str, Any] = asdict(task)
    with tempfile.TemporaryDirectory(prefix="calibproj-study-") as scratch:
        work = Path(scratch)
        sequence = generate(work / "sequence", markers=task.family, arrays=task.arrays, scales=(1.0, 3.0, 6.0),
                            video=False, progress=False)
        scene = _with_condition(load_scene(task.room, seed=task.seed), task.condition)
        simulate_videos(scene, sequence, work / "room", seed=task.seed)
        started = time.perf_counter()
        results = work / "results"
        # Metres from one camera's height, as a user measures it.
        first = scene.cameras[0]
        calibration = calibrate(work / "room" / "videos", work / "room" / "intrinsics",
                                sequence=work / "sequence" / "sequence.json", out=results, progress=False,
                                scale=f"camera-height:{first.name}={first.position[2]:.6f}", report=False)
        row["seconds"] = time.perf_counter() - started
        row["cameras"] = len(scene.cameras)
        row["registered"] = len(calibration.poses)
        weak = {n for n, m in calibration.metrics.items() if m.weak}
        row["weak"] = sorted(weak)
        if len(calibration.poses) >= 3:
            comparison = compare(results / "camera_poses.json", work / "room" / "truth.json")
            strong = [n for n in comparison.cameras if n not in weak]
            row["rotation_rmse_deg"] = _rms([comparison.cameras[n].rotation_deg for n in strong])
            row["translation_rmse_mm"] = _rms([comparison.cameras[n].translation_mm for n in strong])
            evaluation = evaluate(results, work / "room" / "eval_tracks.json",
                                  options=EvaluationOptions(weak_cameras_place_points=False))
            row["eval_mean_px"] = evaluation.mean_px
            row["eval_success_0.5"] = evaluation.success_rate(0.5)
        row["observations"] = int(sum(m.observations for m in calibration.metrics.values()))
        row["msm_centre_rms_px"] = msm_centre_rms(results / "tracks.json", work / "room" / "truth.json")
    return row


def msm_centre_rms(tracks_path: Path, truth_path: Path, wrong_px: float = 3.0) -> float:
    """RMS distance of the ingest's MSM centres (undistorted pixels) to their true image
    positions, over every camera; observations farther than ``wrong_px`` (none, when
    the ingest works) are left out of it."""
    import json

    from calibproj.formats.tracks import Tracks

    tracks = Tracks.read(tracks_path)
    truth = json.loads(truth_path.read_text())["image_points"]
    errors = []
    for name in tracks.camera_names:
        true_xy = dict(zip(truth[name]["ids"], truth[name]["undistorted"]))
        ids, xy = tracks.observations(name)
        for point, observed in zip(ids, xy):
            expected = true_xy.get(int(point))
            if expected is not None:
                errors.append(float(np.hypot(*(np.asarray(observed) - expected))))
    kept = [e for e in errors if e <= wrong_px]
    return float(np.sqrt(np.mean(np.square(kept)))) if kept else math.nan


def _with_condition(scene: Any, condition: str) -> Any:
    if condition == "clean":
        return scene
    if condition == "room-light":
        return replace(scene, photometric=replace(scene.photometric, ambient=0.4, contrast=0.3))
    if condition == "rolling-15ms":
        return replace(scene, cameras=tuple(replace(c, readout_s=0.015) for c in scene.cameras))
    raise ValueError(f"unknown calibration condition {condition!r} (choose from {', '.join(CONDITIONS)})")


def _rms(values: list[float | None]) -> float:
    values = [v for v in values if v is not None]
    return float(np.sqrt(np.mean(np.square(values)))) if values else math.nan
