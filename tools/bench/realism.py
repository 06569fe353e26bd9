"""Real cameras and real rooms: the demo room calibrated from its rendered videos under
each effect alone (two levels) and all combined, over several seeds.

Per condition it prints cameras registered / total (and the failed ones with their
reason), rotation and translation RMSE against the truth after Sim(3) alignment,
evaluation on the rendering's independent points (mean px, success at 0.5 px), the
largest sync error against the truth (camera frames; over the cameras whose offset the
video determines, and over all with the largest excess over the reported uncertainty),
the largest readout error (ms, where a readout is estimated, and in units of its sigma),
and observations assigned to a wrong point (farther than --wrong-px from that point's
true image position). Rotation RMSE and success are also given over the cameras not
reported weak (rotation known worse than the registration's weak_rotation_sigma_deg),
the success on evaluation points that the weak cameras did not place; weak cameras are
listed with their sigma. "Each on points placed without it" holds every camera out of
placing the points it is judged on in turn (``evaluate_held_out``), and the camera with
the longest focal length (the zoomed one) is given with its error and sigma (deg) and its
error held out (px), also with every pose the true one (what its detections and the
others' allow, whatever the registration does).
The last lines: over every camera, ``realism: all cameras: worst_success_alone=..
worst_error_sigmas=.. runs_with_weak=K/N worst_extra_projection_s=..
zoomed_alone_px_at_truth=min..max``; over the runs where the zoomed camera is registered
and not the reference, ``realism: zoomed camera: registered_and_evaluated=K/N
largest_sigma_deg=.. worst_error_sigmas=..``; over the cameras not reported weak,
``realism: worst_rot_deg=.. worst_eval_success=.. registered=A/B worst_sync_frames=..
sync_beyond_frames=.. worst_readout_ms=.. worst_readout_sigmas=.. wrong=N``.
``--summarise JSON...`` prints the rows and last lines of earlier runs' ``--json`` files.
``--out-dir DIR`` keeps each run's row in a file of its own and takes the runs already
there from it (same other options assumed), so that a sweep of many hours resumes where
it stopped; ``tools/bench/results/realism/`` keeps those of the densified sweep behind
README's figures (``--summarise tools/bench/results/realism/*.json``).
With --refine-intrinsics every run also self-calibrates from the true intrinsics: each
row lists the cameras flagged a misfit (a smooth pattern left in their residuals) and the
refined focal lengths' worst error against the truth in sigmas over the others, and a
last line ``realism: lenses: runs_with_misfit=K/N worst_trusted_focal_sigmas=..``.

    python tools/bench/realism.py                       # every condition, 3 seeds
    python tools/bench/realism.py --conditions clean,drops-2 --seeds 1 --arrays 12
    python tools/bench/realism.py --scene or-full --densify --work W --out-dir tools/bench/results/realism
"""

from __future__ import annotations

import argparse
import functools
import json
import logging
import math
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from calibproj.evaluation.comparison import compare, rotation_errors_to_reference
from calibproj.cli.demo_room import marker_side_on_floor
from calibproj.evaluation.independent import EvaluationOptions, evaluate, evaluate_held_out
from calibproj.formats.intrinsics import load_intrinsics_dir
from calibproj.ingest.options import IngestOptions
from calibproj.ingest.videos import VIDEO_SUFFIXES
from calibproj.pipeline import calibrate
from calibproj.registration.driver import RegistrationOptions
from calibproj.sequence import Sequence, generate
from calibproj.sequence.densify import DensifyOptions, densify
from calibproj.simulate.presets import REAL_PEOPLE
from calibproj.simulate.render import RenderOptions, simulate_videos
from calibproj.simulate.scene import (AutoExposure, FloorRelief, FloorTexture, Person, Scene, load_scene,
                                      read_scene)

Effect = Callable[[Scene], Scene]


def cameras(scene: Scene, **changes) -> Scene:
    return replace(scene, cameras=tuple(replace(camera, **changes) for camera in scene.cameras))


def timing(drop_rate: float, jitter_s: float) -> Effect:
    """Dropped frames and jitter (capped where a camera's frame leaves less room)."""
    def apply(scene: Scene) -> Scene:
        return replace(scene, cameras=tuple(
            replace(c, drop_rate=drop_rate, frame_jitter_s=min(jitter_s, (1.0 / c.fps - c.exposure_s) / 6.0))
            for c in scene.cameras))
    return apply


def readout(seconds: float) -> Effect:
    def apply(scene: Scene) -> Scene:
        return replace(scene, cameras=tuple(replace(c, readout_s=min(seconds, 0.9 / c.fps)) for c in scene.cameras))
    return apply


def photometric(**changes) -> Effect:
    return lambda scene: replace(scene, photometric=replace(scene.photometric, **changes))


def texture(**changes) -> Effect:
    return lambda scene: replace(scene, floor=replace(scene.floor, texture=FloorTexture(**changes)))


def relief(rms_m: float) -> Effect:
    """A slightly uneven floor (``run`` gives it the run's seed)."""
    return lambda scene: replace(scene, floor=replace(scene.floor, relief=FloorRelief(rms_m=rms_m)))


# name -> (scene effect, render option changes)
CONDITIONS: dict[str, tuple[Effect, dict]] = {
    "clean": (lambda scene: scene, {}),
    "drops-2": (timing(0.02, 0.001), {}),
    "drops-5": (timing(0.05, 0.002), {}),
    "auto-exposure": (lambda s: cameras(s, auto_exposure=AutoExposure()), {}),
    "auto-exposure-fast": (lambda s: cameras(s, auto_exposure=AutoExposure(target=0.6, time_constant_s=0.15)), {}),
    "room-light": (photometric(ambient=0.2, contrast=0.5), {}),
    "room-light-strong": (photometric(ambient=0.4, contrast=0.3), {}),
    "floor": (texture(), {}),
    "floor-strong": (texture(grout_albedo=0.25, stains=60, stain_albedo=0.35, tile_albedo_std=0.08), {}),
    "crf-24": (lambda scene: scene, {"crf": 24}),
    "crf-30": (lambda scene: scene, {"crf": 30}),
    "rolling-15ms": (readout(0.015), {}),
    "rolling-30ms": (readout(0.030), {}),
    "people": (lambda scene: replace(scene, people=tuple(Person(**p) for p in REAL_PEOPLE)), {}),
    "uneven-floor": (relief(0.003), {}),
    "uneven-floor-strong": (relief(0.006), {}),
}
COMBINED = "all"


def combined(*names: str) -> Effect:
    def apply(scene: Scene) -> Scene:
        for name in names:
            scene = CONDITIONS[name][0](scene)
        return scene
    return apply


# Every effect at once; and the same with exposures locked, as a careful user sets them
# (room light and floor texture then reach the detector undimmed by a gain: this
# combination once cost a 60 fps camera every marker).
CONDITIONS[COMBINED] = (combined("drops-2", "auto-exposure", "room-light", "floor", "rolling-15ms", "people"),
                        {"crf": 24})
CONDITIONS["all-locked"] = (combined("drops-2", "room-light", "floor", "rolling-15ms", "people"), {"crf": 24})


def run(condition: str, seed: int, sequence, sequence_path: Path, work: Path, args) -> dict:
    effect, render_changes = CONDITIONS[condition]
    scene = effect(load_scene(args.scene, seed=seed))
    if scene.floor.relief is not None:  # each seed its own floor
        scene = replace(scene, floor=replace(scene.floor, relief=replace(scene.floor.relief, seed=seed)))
    room = work / f"{condition}-{seed}"
    first_kept = ("first_tracks.json", "first_detect_report.json") if args.reuse_detections else ()
    if not (args.reuse and rendered(room, scene, first_kept)):
        for kept in ("first_tracks.json", "first_detect_report.json"):  # of another rendering
            (room / kept).unlink(missing_ok=True)
        simulate_videos(scene, sequence, room, seed=seed, options=replace(RenderOptions(), **render_changes))
    marker_side_m = marker_side_on_floor(room / "scene.json", sequence)
    results = room / "results"
    calibrate_room = functools.partial(
        calibrate_scaled, intrinsics=room / "intrinsics", scale=f"marker-size:{marker_side_m:.9f}",
        options=RegistrationOptions(model=args.model, use_projector=not args.no_projector, **args.registration_option),
        exposures=locked_exposures(scene) if args.locked_exposures else None, label=f"{condition} seed {seed}",
        refine_intrinsics=args.refine_intrinsics,
        # None leaves calibrate its own choice (a lens to refine relaxes the ingest).
        ingest_options=IngestOptions(**args.ingest_option) if args.ingest_option else None)
    calibration = calibrate_first(calibrate_room, room, sequence_path, results, reused=args.reuse_detections)
    extra_s = 0.0
    if args.densify:
        dense, _ = densify(results, Sequence.load(sequence_path), DensifyOptions(max_seconds=args.densify_seconds))
        if dense is not None:
            extra_s = dense.duration_s
            planned = room / "dense_sequence.json"
            same_plan = planned.is_file() and Sequence.load(planned) == dense
            dense_kept = ("../dense_tracks.json",) if args.reuse_detections else ()
            dense_reused = args.reuse and same_plan and rendered(room / "dense", scene, dense_kept)
            if not dense_reused:
                planned.unlink(missing_ok=True)  # written once its rendering is complete
                simulate_videos(scene, dense, room / "dense", seed=seed + 1000,
                                options=replace(RenderOptions(), **render_changes))
                dense.save(planned)
            results = room / "results_dense"
            calibration = calibrate_dense(calibrate_room, room, results, reused=args.reuse_detections and dense_reused)
    truth = json.loads((room / "truth.json").read_text())
    report = json.loads(((room / "results") / "detect_report.json").read_text())
    row = {"scene": args.scene, "condition": condition, "seed": seed, "total": len(scene.cameras), "extra_s": extra_s,
           "zoomed": max(scene.cameras, key=lambda camera: camera.fx).name,
           "failed": {name: reason for name, reason in calibration.failed.items()}}
    registered = [name for name in scene.camera_names if name in calibration.poses]
    row["registered"] = len(registered)
    row["weak"] = {name: m.rotation_sigma_deg for name, m in calibration.metrics.items() if m.weak}
    if len(registered) >= 3:
        comparison = compare(results / "camera_poses.json", room / "truth.json")
        evaluation = evaluate(results, room / "eval_tracks.json")
        row.update(rot=comparison.rotation_rmse_deg, mm=comparison.translation_rmse_mm,
                   eval_px=evaluation.mean_px, success=evaluation.success_rate(0.5) / 100.0)
        # The same over the cameras not reported weak, judged on points the weak ones did
        # not place.
        strong = [name for name in comparison.cameras if name not in row["weak"]]
        row["rot_strong"] = rms([comparison.cameras[name].rotation_deg for name in strong])
        strict = evaluate(results, room / "eval_tracks.json", options=EvaluationOptions(weak_cameras_place_points=False))
        passed = [strict.cameras[name].mean_px is not None and strict.cameras[name].mean_px < 0.5
                  for name in strong if name in strict.cameras]
        row["success_strong"] = float(np.mean(passed)) if passed else math.nan
        # Every camera on points placed without it (weak or not: a zoomed camera's precise
        # views would pull the points it is judged on towards its own pose), and each
        # camera's rotation error in units of its reported sigma (the reference has none).
        held_out = evaluate_held_out(results, room / "eval_tracks.json")
        row["alone_px"] = {name: held_out[name].mean_px for name in comparison.cameras if name in held_out}
        alone = [held_out[name].mean_px is not None and held_out[name].mean_px < 0.5
                 for name in comparison.cameras if name in held_out]
        row["success_alone"] = float(np.mean(alone)) if alone else math.nan
        row["alone_px_at_truth"] = held_out_at_truth(calibration, scene, room, row["zoomed"])
        # The sigma is relative to the reference camera (sigma 0): so is this error.
        relative = errors_to_reference(calibration, scene)
        row["sigmas"] = {name: relative[name] / calibration.metrics[name].rotation_sigma_deg for name in relative}
        row["sigma_deg"] = {name: calibration.metrics[name].rotation_sigma_deg for name in relative}
        row["rot_deg"] = relative
    row["sync_frames"] = max_sync_error(report, truth)
    row["readout_ms"] = max_readout_error(report, truth)
    row["wrong"] = wrong_assignments(room / "results" / "tracks.json", truth, args.wrong_px)
    if args.refine_intrinsics:
        row["lenses"] = lens_errors(results / "self_calibration.json", room / "intrinsics")
    return row


def lens_errors(self_calibration: Path, truth: Path) -> dict[str, dict]:
    """Per camera of a self-calibration: the smooth pattern left in its residuals (px),
    whether it was flagged a misfit, and for a refined focal length its error against
    the rendering's true one in units of its reported sigma."""
    document = json.loads(self_calibration.read_text())
    true_focal = {name: camera.K[0, 0] for name, camera in load_intrinsics_dir(truth).items()}
    out = {}
    for name, camera in document["cameras"].items():
        refined = "focal" in camera["refined"] and camera["focal_sigma"]
        error = camera["result"]["focal"] - true_focal[name]
        out[name] = {"pattern_px": camera["systematic_px"], "misfit": camera["misfit"] is not None,
                     "focal_sigmas": error / camera["focal_sigma"] if refined else None}
    return out


def format_lenses(lenses: dict[str, dict]) -> str:
    """The self-calibration's figures of a row: flagged cameras, the largest pattern of
    the others, and the refined focal lengths' worst error in sigmas (flagged or not)."""
    flagged = ", ".join(f"{name} ({lens['pattern_px']:.3f} px)" for name, lens in lenses.items() if lens["misfit"])
    patterns = [lens["pattern_px"] for lens in lenses.values() if not lens["misfit"] and lens["pattern_px"] is not None]
    trusted = [abs(lens["focal_sigmas"]) for lens in lenses.values()
               if lens["focal_sigmas"] is not None and not lens["misfit"]]
    largest, worst = max(patterns, default=math.nan), max(trusted, default=math.nan)
    return (f"  lenses: misfit {flagged or 'none'}, largest pattern otherwise {largest:.3f} px, trusted focal "
            f"within {worst:.1f} sigma")


def calibrate_first(calibrate_room, room: Path, sequence_path: Path, results: Path, reused: bool):
    """The first calibration of ``room``: from its videos, or with ``reused`` from the
    detections an earlier run kept of the same rendering (the ingest does not depend on
    the registration's options). Its detections and detect report are kept beside."""
    kept_tracks, kept_report = room / "first_tracks.json", room / "first_detect_report.json"
    if reused and kept_tracks.is_file() and kept_report.is_file():
        calibration = calibrate_room(kept_tracks, sequence_path, results)
        shutil.copyfile(kept_report, results / "detect_report.json")
        return calibration
    calibration = calibrate_room(room / "videos", sequence_path, results)
    shutil.copyfile(results / "tracks.json", kept_tracks)
    shutil.copyfile(results / "detect_report.json", kept_report)
    return calibration


def calibrate_dense(calibrate_room, room: Path, results: Path, reused: bool):
    """The calibration of ``room`` with its extra projection merged: from the extra
    videos, or with ``reused`` from the merged detections an earlier run kept of the same
    plan and rendering. The merged detections are kept beside."""
    kept_tracks = room / "dense_tracks.json"
    if reused and kept_tracks.is_file():
        return calibrate_room(kept_tracks, room / "dense_sequence.json", results)
    calibration = calibrate_room(room / "dense" / "videos", room / "dense_sequence.json", results,
                                 merge=room / "results")
    shutil.copyfile(results / "tracks.json", kept_tracks)
    return calibration


def calibrate_scaled(videos: Path, sequence: Path, results: Path, *, intrinsics: Path, scale: str,
                     options: RegistrationOptions, exposures, label: str, merge: Path | None = None,
                     refine_intrinsics: list[str] | None = None, ingest_options: IngestOptions | None = None):
    """calibrate() into ``results`` with a metric scale; results in arbitrary units
    (logged) when the scale cannot be measured."""
    # An earlier run's results must not pass for this one's when the calibration fails
    # before it writes any.
    (results / "camera_poses.json").unlink(missing_ok=True)
    try:
        return calibrate(videos, intrinsics, sequence=sequence, out=results, options=options, exposures=exposures,
                         scale=scale, force=True, progress=False, merge=merge, refine_intrinsics=refine_intrinsics,
                         ingest_options=ingest_options)
    except ValueError as error:
        logging.warning("%s: %s", label, error)
        if not (results / "camera_poses.json").is_file():
            raise
        from calibproj.formats.calibration import Calibration

        return Calibration.load(results)


def held_out_at_truth(calibration, scene: Scene, room: Path, name: str) -> float | None:
    """The mean error (px) of camera ``name`` on evaluation points placed without it when
    every pose is the rendering's true one: what the detections alone allow, whatever
    the registration does (None when it is not registered or has no such points)."""
    if name not in calibration.poses:
        return None
    true_poses = {camera.name: (camera.R, camera.t) for camera in scene.cameras if camera.name in calibration.poses}
    at_truth = evaluate(calibration.replace(poses=true_poses), room / "eval_tracks.json", room / "intrinsics",
                        EvaluationOptions(held_out=(name,)))
    judged = at_truth.cameras.get(name)
    return None if judged is None else judged.mean_px


def errors_to_reference(calibration, scene: Scene) -> dict[str, float]:
    """Per registered camera but the reference (rotation sigma 0, the gauge of the
    covariance), its rotation error relative to the reference (deg)."""
    sigma = {name: calibration.metrics[name].rotation_sigma_deg for name in calibration.poses}
    reference = next((name for name, value in sigma.items() if value == 0.0), None)
    if reference is None:
        return {}
    errors = rotation_errors_to_reference(calibration.poses, reference, {c.name: c.R for c in scene.cameras})
    return {name: error for name, error in errors.items() if sigma[name]}


def rendered(room: Path, scene: Scene, kept: tuple[str, ...] = ()) -> bool:
    """The room folder already holds a complete rendering of this scene, with its videos
    or, where ``kept`` names them, the detections kept of them (a sweep deletes the
    videos)."""
    try:
        same = (room / "truth.json").is_file() and read_scene(room / "scene.json") == scene
    except (OSError, ValueError):
        return False
    videos = room / "videos"
    has_videos = videos.is_dir() and any(path.suffix in VIDEO_SUFFIXES for path in videos.iterdir())
    return same and (has_videos or bool(kept) and all((room / name).is_file() for name in kept))


def locked_exposures(scene: Scene) -> dict[str, float]:
    """The exposure times a user who locked them knows: every camera's but those with
    automatic exposure."""
    return {camera.name: camera.exposure_s for camera in scene.cameras if camera.auto_exposure is None}


def rms(values: list[float]) -> float:
    return float(np.sqrt(np.mean(np.square(values)))) if values else math.nan


def max_sync_error(report: dict, truth: dict) -> dict[str, float]:
    """Sync errors against the truth (camera frames): the largest over the cameras whose
    offset the video determines (``sharp``: some frames straddle a light change), the
    largest over all cameras, and the largest excess over the reported uncertainty (0
    when every truth lies within its interval). A camera whose frames keep a fixed
    phase to the projector's and never straddle a light change records the same video
    for any offset inside its interval: there the interval is what can be known."""
    determined, worst, beyond = 0.0, 0.0, 0.0
    for name, camera in report["cameras"].items():
        if camera["status"] != "ok":
            continue
        timing = truth["timing"]["cameras"][name]
        true_offset = -timing["first_exposure_start_s"] * timing["fps"]
        error = abs(camera["sync"]["offset_frames"] - true_offset)
        worst = max(worst, error)
        if camera["sync"]["sharp"]:
            determined = max(determined, error)
        beyond = max(beyond, error - camera["sync"]["offset_uncertainty_frames"])
    return {"determined": determined, "all": worst, "beyond": max(beyond, 0.0)}


def max_readout_error(report: dict, truth: dict) -> tuple[float, float] | None:
    """The largest readout error (ms) over the cameras whose readout is estimated, and
    the largest error in units of the camera's reported sigma; None without any."""
    errors = [(abs(camera["sync"]["readout_s"] - truth["timing"]["cameras"][name]["readout_s"]) * 1e3,
               camera["sync"]["readout_sigma_s"] * 1e3)
              for name, camera in report["cameras"].items()
              if camera["status"] == "ok" and camera["sync"].get("readout_s") is not None]
    if not errors:
        return None
    return max(error for error, _ in errors), max(error / max(sigma, 1e-9) for error, sigma in errors)


def wrong_assignments(tracks_path: Path, truth: dict, threshold_px: float) -> int:
    """Observations farther than threshold_px from their point's true (distorted) image position."""
    from calibproj.formats.tracks import Tracks

    tracks = Tracks.read(tracks_path)
    wrong = 0
    for name in tracks.camera_names:
        points = truth["image_points"][name]
        true_xy = dict(zip(points["ids"], points["undistorted"]))
        ids, xy = tracks.observations(name)
        for point, observed in zip(ids, xy):
            expected = true_xy.get(int(point))
            if expected is None or np.hypot(*(np.asarray(observed) - expected)) > threshold_px:
                wrong += 1
    return wrong


def format_sync(sync: dict[str, float]) -> str:
    return (f"sync {sync['determined']:.3f} fr where determined (all {sync['all']:.3f}, "
            f"beyond +-: {sync['beyond']:.3f})")


def worst_ratio(row: dict) -> float:
    return max(row["sigmas"].values(), default=math.nan)


def zoomed(row: dict) -> str:
    """The camera with the longest focal length: its error and sigma (deg), and its mean
    error on evaluation points placed without it (px)."""
    name = row["zoomed"]
    if name not in row["sigma_deg"]:
        return f"{name} not registered or the reference"
    alone, at_truth = row["alone_px"].get(name), row.get("alone_px_at_truth")
    return (f"{name} {row['rot_deg'][name]:.4f}/{row['sigma_deg'][name]:.4f} deg "
            f"{'-' if alone is None else f'{alone:.3f}'} px alone "
            f"({'-' if at_truth is None else f'{at_truth:.3f}'} px at the true poses)")


def run_label(row: dict) -> str:
    """Scene (rows written before it was kept have none), condition and seed."""
    return f"{row.get('scene', ''):<7} {row['condition']:<20} seed {row['seed']}"


def format_row(row: dict) -> str:
    failed = "; ".join(f"{name}: {reason[:80]}" for name, reason in row["failed"].items())
    weak = ", ".join(f"{name} ({sigma:.3f} deg)" for name, sigma in row["weak"].items())
    readout = "-" if row["readout_ms"] is None else f"{row['readout_ms'][0]:.2f} ({row['readout_ms'][1]:.1f} sigma)"
    if "rot" not in row:
        return (f"{run_label(row)}  registered {row['registered']}/{row['total']}  "
                f"{format_sync(row['sync_frames'])}  {failed}")
    mm = "-" if row["mm"] is None else f"{row['mm']:.2f}"
    return (f"{run_label(row)}  registered {row['registered']}/{row['total']}  "
            f"rot {row['rot']:.4f} deg (not weak {row['rot_strong']:.4f})  {mm} mm  eval {row['eval_px']:.3f} px  "
            f"@0.5 {100 * row['success']:.0f} % (not weak {100 * row['success_strong']:.0f} %, each on points "
            f"placed without it {100 * row['success_alone']:.0f} %)  worst error/sigma {worst_ratio(row):.1f} "
            f"(to the reference camera)  "
            + (f"extra projection {row['extra_s']:.1f} s  " if row["extra_s"] else "") +
            f"zoomed {zoomed(row)}  "
            f"{format_sync(row['sync_frames'])}  "
            f"readout {readout} ms  wrong {row['wrong']}"
            + (f"  weak: {weak}" if weak else "") + (f"  failed: {failed}" if failed else "")
            + (format_lenses(row["lenses"]) if "lenses" in row else ""))


def option_changes(items: list[str], options_class, flag: str) -> dict:
    """``NAME=VALUE`` items as fields of ``options_class``, each value read as its default's type."""
    defaults = options_class()
    changes = {}
    for item in items:
        name, _, value = item.partition("=")
        if not hasattr(defaults, name) or not value:
            raise ValueError(f"{flag} {item!r}: expected NAME=VALUE with NAME a field of {options_class.__name__}")
        kind = type(getattr(defaults, name))
        changes[name] = value.lower() in ("1", "true", "yes") if kind is bool else kind(value)
    options_class(**changes)  # its own checks, before any rendering
    return changes


def summarise(rows: list[dict], lenses: bool) -> None:
    """The last lines: the worst of every run (module docstring)."""
    evaluated = [row for row in rows if "rot" in row]
    # Over the cameras not reported weak: a weak camera is reported with its sigma.
    worst_rot = max((row["rot_strong"] for row in evaluated), default=math.nan)
    worst_success = min((row["success_strong"] for row in evaluated), default=math.nan)
    registered = sum(row["registered"] for row in rows)
    total = sum(row["total"] for row in rows)
    worst_sync = max((row["sync_frames"]["determined"] for row in rows), default=math.nan)
    beyond = max((row["sync_frames"]["beyond"] for row in rows), default=math.nan)
    readouts = [row["readout_ms"] for row in rows if row["readout_ms"] is not None]
    worst_readout = max((error for error, _ in readouts), default=math.nan)
    worst_readout_sigmas = max((sigmas for _, sigmas in readouts), default=math.nan)
    wrong = sum(row["wrong"] for row in rows)
    worst_alone = min((row["success_alone"] for row in evaluated), default=math.nan)
    worst_sigmas = max((worst_ratio(row) for row in evaluated), default=math.nan)
    weak_runs = sum(bool(row["weak"]) for row in rows)
    worst_extra = max((row["extra_s"] for row in rows), default=0.0)
    at_truth = [row["alone_px_at_truth"] for row in evaluated if row.get("alone_px_at_truth") is not None]
    zoomed_rows = [row for row in evaluated if row["zoomed"] in row["sigma_deg"]]
    zoomed_sigma = max((row["sigma_deg"][row["zoomed"]] for row in zoomed_rows), default=math.nan)
    zoomed_sigmas = max((row["sigmas"][row["zoomed"]] for row in zoomed_rows), default=math.nan)
    print(f"realism: all cameras: worst_success_alone={worst_alone:.3f} worst_error_sigmas={worst_sigmas:.2f} "
          f"runs_with_weak={weak_runs}/{len(rows)} worst_extra_projection_s={worst_extra:.1f} "
          f"zoomed_alone_px_at_truth={min(at_truth, default=math.nan):.3f}..{max(at_truth, default=math.nan):.3f}")
    print(f"realism: zoomed camera: registered_and_evaluated={len(zoomed_rows)}/{len(rows)} "
          f"largest_sigma_deg={zoomed_sigma:.4f} worst_error_sigmas={zoomed_sigmas:.2f}")
    print(f"realism: worst_rot_deg={worst_rot:.4f} worst_eval_success={worst_success:.3f} "
          f"registered={registered}/{total} worst_sync_frames={worst_sync:.3f} sync_beyond_frames={beyond:.3f} "
          f"worst_readout_ms={worst_readout:.2f} worst_readout_sigmas={worst_readout_sigmas:.1f} wrong={wrong}")
    if lenses:
        per_run = [list(row.get("lenses", {}).values()) for row in rows]
        flagged = sum(any(lens["misfit"] for lens in run) for run in per_run)
        trusted = [abs(lens["focal_sigmas"]) for run in per_run for lens in run
                   if lens["focal_sigmas"] is not None and not lens["misfit"]]
        print(f"realism: lenses: runs_with_misfit={flagged}/{len(rows)} "
              f"worst_trusted_focal_sigmas={max(trusted, default=math.nan):.1f}")


def summarise_files(paths: list[Path]) -> int:
    """The rows and last lines of earlier runs' --json files; 2 with one line when one is
    not such a file."""
    rows = []
    for path in paths:
        try:
            loaded = json.loads(path.read_text())
            if not isinstance(loaded, list) or not all(isinstance(row, dict) and "condition" in row for row in loaded):
                raise ValueError("not a list of realism rows")
        except (OSError, ValueError) as error:
            print(f"realism: {path}: {error}", file=sys.stderr)
            return 2
        rows += loaded
    for row in rows:
        print(format_row(row))
    summarise(rows, lenses=any("lenses" in row for row in rows))
    return 0


def write_rows(path: Path, rows: list[dict]) -> None:
    """Rows as JSON, whole or not at all (a stopped sweep leaves no half-written run)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".part")
    partial.write_text(json.dumps(rows, indent=1) + "\n")
    partial.replace(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", default="demo", help="scene preset (default demo)")
    parser.add_argument("--conditions", default=",".join(CONDITIONS),
                        help=f"comma-separated conditions (default all: {', '.join(CONDITIONS)})")
    parser.add_argument("--seeds", type=int, default=3, help="seeds per condition (default 3)")
    parser.add_argument("--first-seed", type=int, default=0,
                        help="first seed; seeds first..first+N-1 are run (default 0)")
    parser.add_argument("--arrays", type=int, default=48, help="MSM arrays projected (default 48, as the demo)")
    parser.add_argument("--markers", default="aruco:4X4_50", help="marker family (default aruco:4X4_50)")
    parser.add_argument("--model", default="coplanar", choices=("coplanar", "free"))
    parser.add_argument("--no-projector", action="store_true",
                        help="leave the projector out of the model (the registration's use_projector off), for comparison")
    parser.add_argument("--wrong-px", type=float, default=3.0,
                        help="an observation this far from its point's true position counts as wrong (default 3)")
    parser.add_argument("--locked-exposures", action="store_true",
                        help="give the calibration the exposure time of every camera without automatic exposure "
                             "(calibrate --exposure), as a user who locked them knows them")
    parser.add_argument("--work", type=Path, default=None, help="keep renderings here (default: a temporary folder)")
    parser.add_argument("--reuse", action="store_true",
                        help="with --work: calibrate the renderings already there again where their scene is the "
                             "condition's (same --arrays and --markers assumed) instead of rendering them anew")
    parser.add_argument("--reuse-detections", action="store_true",
                        help="with --reuse: calibrate a reused rendering from the detections of its first projection, "
                             "and of its extra one where the plan is the same, that an earlier run kept (they depend "
                             "on the rendering and the ingest only)")
    parser.add_argument("--densify", action="store_true",
                        help="after the first calibration, render the extra projection `calibproj generate --densify` "
                             "plans for its weak cameras and calibrate again with --merge")
    parser.add_argument("--densify-seconds", type=float, default=DensifyOptions.max_seconds,
                        help="longest extra projection (default %(default)s)")
    parser.add_argument("--registration-option", metavar="NAME=VALUE", action="append", default=[],
                        help="a RegistrationOptions field set for every calibration, e.g. relief_cells=16 "
                             "(repeatable; default none)")
    parser.add_argument("--ingest-option", metavar="NAME=VALUE", action="append", default=[],
                        help="an IngestOptions field set for every detection, e.g. scale_drift=0 (repeatable; "
                             "default none)")
    parser.add_argument("--refine-intrinsics", metavar="[CAMERA=]ENTRIES", action="append", default=None,
                        help="self-calibrate every run from the true intrinsics (as calibrate's flag); each row "
                             "then lists the cameras flagged a misfit and the refined focal lengths' worst error "
                             "in sigmas over the others")
    parser.add_argument("--json", type=Path, default=None, help="also write every row to this JSON file")
    parser.add_argument("--out-dir", type=Path, default=None,
                        help="also keep each run's row in DIR/SCENE-CONDITION-sSEED.json, written once the run is "
                             "complete, and take a run whose file is there from it instead of running it again "
                             "(a long sweep resumes where it stopped; default: none)")
    parser.add_argument("--summarise", metavar="JSON", type=Path, nargs="+", default=None,
                        help="run nothing: print the rows and last lines of earlier runs' --json files together")
    args = parser.parse_args(argv)
    if args.summarise:
        return summarise_files(args.summarise)
    try:
        args.registration_option = option_changes(args.registration_option, RegistrationOptions,
                                                  "--registration-option")
        args.ingest_option = option_changes(args.ingest_option, IngestOptions, "--ingest-option")
    except ValueError as error:
        parser.error(str(error))
    if args.ingest_option and args.reuse_detections:
        parser.error("--ingest-option changes the detections, which --reuse-detections takes as kept")
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    names = [name.strip() for name in args.conditions.split(",") if name.strip()]
    unknown = sorted(set(names) - set(CONDITIONS))
    if unknown:
        parser.error(f"unknown condition(s) {', '.join(unknown)} (choose from {', '.join(CONDITIONS)})")
    with tempfile.TemporaryDirectory(prefix="realism-") as scratch:
        work = args.work or Path(scratch)
        work.mkdir(parents=True, exist_ok=True)
        sequence = generate(work / "sequence", markers=args.markers, arrays=args.arrays, scales=(1.0, 3.0, 6.0),
                            progress=False)
        rows = []
        for name in names:
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                kept = None if args.out_dir is None else args.out_dir / f"{args.scene}-{name}-s{seed}.json"
                if kept is not None and kept.is_file():
                    row, = json.loads(kept.read_text())
                else:
                    started = time.perf_counter()
                    row = run(name, seed, sequence, work / "sequence" / "sequence.json", work, args)
                    row["seconds"] = time.perf_counter() - started
                    if kept is not None:
                        write_rows(kept, [row])
                rows.append(row)
                print(format_row(row), flush=True)
    if args.json:
        write_rows(args.json, rows)
    summarise(rows, lenses=bool(args.refine_intrinsics))
    return 0


if __name__ == "__main__":
    sys.exit(main())
