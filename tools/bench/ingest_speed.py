"""Ingest speed on a rendered mock operating room: decode + sync + detect per camera
against `ffmpeg -i VIDEO -f null -` on the same file, in the same run.

The `or-full` room (9 cameras at 1920x1080, 25 to 60 fps) is rendered once per marker
system with the paper's sequence (100 arrays of 4 x 8 markers, 7 scales) into
--render-dir (default: a temporary folder, removed afterwards; give a folder to keep the
renderings and reuse them in later runs). Each camera is then ingested on its own (its
video decoded by FFmpeg's threads while a detection thread works) and decoded by the
ffmpeg program (before and after, averaged), so that both see the same machine load.
Per camera it prints both wall times, their ratio and the ratio of CPU times (steadier
on a shared machine), the frames and MSMs, and the MSM centre error against the
rendering's truth (RMS over MSMs whose detected markers are at least 20 px wide).

The last line is

  ingest: ratio_to_ffmpeg_decode=X together_cpu_ratio=T aruco_ms_per_frame=A apriltag_ms_per_frame=B

with X the summed ingest time over the summed ffmpeg decode time (every camera of
every marker system), T the CPU time of ingesting every camera together (as many at
once as there are cores, as an operating-room PC runs its cameras) over that of the
ffmpeg decodes, and A, B the detection time per detected pattern frame
(detection-thread time over frames handed to detection) for each system.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from calibproj.sequence.builder import build_sequence
from calibproj.sequence.sequence import Sequence
from calibproj.ingest.videos import ingest
from calibproj.ingest.options import IngestOptions

SYSTEMS = {"aruco": "aruco:4X4_50", "apriltag": "apriltag:tag36h11"}
MIN_SIDE_PX = 20.0


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--render-dir", metavar="DIR",
                        help="folder holding (or receiving) the renderings (default: a temporary folder)")
    parser.add_argument("--scene", default="or-full", help="scene preset or scene.json (default or-full)")
    parser.add_argument("--systems", default="aruco,apriltag", help="marker systems to run (default aruco,apriltag)")
    parser.add_argument("--arrays", type=int, default=100, help="MSM arrays of the sequence (default 100)")
    parser.add_argument("--cameras", help="comma-separated cameras to measure (default: all)")
    parser.add_argument("--seed", type=int, default=0, help="render seed (default 0)")
    return parser.parse_args()


def rendering(folder: Path, scene: str, markers: str, arrays: int, seed: int) -> tuple[Path, Sequence]:
    """The rendering in `folder`, made first if it is missing or of another sequence."""
    from calibproj.simulate.render import simulate_videos

    sequence = build_sequence(markers=markers, arrays=arrays)
    sequence_file = folder / "sequence.json"
    if (folder / "sim" / "truth.json").is_file() and sequence_file.is_file() and \
            Sequence.load(sequence_file) == sequence:
        return folder, sequence
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    started = time.perf_counter()
    print(f"rendering {scene} with {markers} ({arrays} arrays) into {folder} ...", flush=True)
    simulate_videos(scene, sequence, folder / "sim", seed=seed, progress=sys.stderr.isatty())
    sequence.save(sequence_file)
    print(f"rendered in {time.perf_counter() - started:.0f} s", flush=True)
    return folder, sequence


def cpu_seconds(who: int) -> float:
    usage = resource.getrusage(who)
    return usage.ru_utime + usage.ru_stime


def ffmpeg_decode(video: Path) -> tuple[float, float]:
    """Wall and CPU seconds of `ffmpeg -i VIDEO -f null -`."""
    started, cpu = time.perf_counter(), cpu_seconds(resource.RUSAGE_CHILDREN)
    subprocess.run(["ffmpeg", "-v", "error", "-nostdin", "-i", str(video), "-f", "null", "-"], check=True)
    return time.perf_counter() - started, cpu_seconds(resource.RUSAGE_CHILDREN) - cpu


def centre_rms(camera, truth: dict, markers_per_array: int) -> tuple[float, int]:
    """RMS error (px) of the merged centres whose kept markers are all >= MIN_SIDE_PX."""
    raw = camera.raw
    points = truth["image_points"][camera.name]
    true_xy = dict(zip(points["ids"], points["undistorted"]))
    records, centres = raw.records, raw.centres
    record_ids = records.array * markers_per_array + records.marker
    errors = []
    for array, marker, xy in zip(centres.array, centres.marker, centres.xy):
        point = int(array) * markers_per_array + int(marker)
        kept = (record_ids == point) & records.kept
        if point in true_xy and records.side_px[kept].min() >= MIN_SIDE_PX:
            errors.append(np.linalg.norm(xy - true_xy[point]))
    return (float(np.sqrt(np.mean(np.square(errors)))) if errors else float("nan")), len(errors)


def measure(system: str, folder: Path, sequence: Sequence, cameras: list[str] | None) -> dict:
    sim = folder / "sim"
    truth = json.loads((sim / "truth.json").read_text())
    names = cameras or sorted(p.stem for p in (sim / "videos").glob("*.mp4"))
    totals = {"ingest": 0.0, "ffmpeg": 0.0, "ingest_cpu": 0.0, "ffmpeg_cpu": 0.0, "detection": 0.0, "frames": 0}
    print(f"\n{system}: {'camera':<9}{'ffmpeg s':>9}{'ingest s':>9}{'ratio':>7}{'cpu ratio':>10}{'decoded':>8}"
          f"{'detect':>7}{'det ms':>7}{'MSMs':>6}{'rms px':>8}{'n':>5}  sync")
    for name in names:
        video = sim / "videos" / f"{name}.mp4"
        # ffmpeg before and after the ingest, averaged: the machine's load drifts.
        before = ffmpeg_decode(video)
        started, cpu = time.perf_counter(), cpu_seconds(resource.RUSAGE_SELF)
        result = ingest({name: video}, sequence, sim / "intrinsics", options=IngestOptions(), workers=1,
                        progress=False)
        ingest_s, ingest_cpu = time.perf_counter() - started, cpu_seconds(resource.RUSAGE_SELF) - cpu
        after = ffmpeg_decode(video)
        ffmpeg_s, ffmpeg_cpu = 0.5 * (before[0] + after[0]), 0.5 * (before[1] + after[1])
        camera = result.cameras[name]
        if not camera.ok:
            print(f"{system}: {name:<9}{ffmpeg_s:9.2f}{ingest_s:9.2f}  FAILED: {camera.error}")
            continue
        raw = camera.raw
        rms, count = centre_rms(camera, truth, result.tracks.markers_per_array)
        detected = raw.frames_detected
        detect_ms = 1e3 * raw.seconds_detection / max(detected, 1)
        sync = raw.sync
        print(f"{system}: {name:<9}{ffmpeg_s:9.2f}{ingest_s:9.2f}{ingest_s / ffmpeg_s:7.2f}"
              f"{ingest_cpu / ffmpeg_cpu:10.2f}{raw.frames_decoded:8d}"
              f"{detected:7d}{detect_ms:7.1f}{len(raw.centres.array):6d}{rms:8.3f}{count:5d}"
              f"  offset {sync.map.offset:.3f}+-{sync.offset_uncertainty:.3f} rate {sync.map.rate:.6f}", flush=True)
        totals["ingest"] += ingest_s
        totals["ffmpeg"] += ffmpeg_s
        totals["ingest_cpu"] += ingest_cpu
        totals["ffmpeg_cpu"] += ffmpeg_cpu
        totals["detection"] += raw.seconds_detection
        totals["frames"] += detected
    print(f"{system}: total ffmpeg {totals['ffmpeg']:.1f} s, ingest {totals['ingest']:.1f} s, "
          f"ratio {totals['ingest'] / max(totals['ffmpeg'], 1e-9):.2f} "
          f"(CPU {totals['ingest_cpu'] / max(totals['ffmpeg_cpu'], 1e-9):.2f}), "
          f"detection {1e3 * totals['detection'] / max(totals['frames'], 1):.1f} ms per pattern frame")
    totals["together_cpu"] = together(sim, sequence, names)
    print(f"{system}: every camera ingested together ({os.cpu_count()} at once, sharing the cores): "
          f"CPU {totals['together_cpu']:.1f} s, {totals['together_cpu'] / max(totals['ffmpeg_cpu'], 1e-9):.2f}x "
          "the separate ffmpeg decodes")
    return totals


def together(sim: Path, sequence: Sequence, names: list[str]) -> float:
    """CPU seconds of one ingest of every camera, as many at once as there are cores (as
    an operating-room PC runs its cameras): FFmpeg's threads are then shared among them."""
    cpu = cpu_seconds(resource.RUSAGE_SELF)
    ingest({name: sim / "videos" / f"{name}.mp4" for name in names}, sequence, sim / "intrinsics",
           options=IngestOptions(), workers=os.cpu_count() or 1, progress=False)
    return cpu_seconds(resource.RUSAGE_SELF) - cpu


def main() -> int:
    args = parse_args()
    systems = [s.strip() for s in args.systems.split(",") if s.strip()]
    unknown = sorted(set(systems) - set(SYSTEMS))
    if unknown:
        raise SystemExit(f"unknown marker system(s) {unknown} (choose from {', '.join(SYSTEMS)})")
    cameras = args.cameras.split(",") if args.cameras else None
    temporary = None if args.render_dir else tempfile.mkdtemp(prefix="ingest_speed_")
    root = Path(args.render_dir or temporary)
    try:
        totals = {}
        for system in systems:
            folder, sequence = rendering(root / system, args.scene, SYSTEMS[system], args.arrays, args.seed)
            totals[system] = measure(system, folder, sequence, cameras)
    finally:
        if temporary:
            shutil.rmtree(temporary, ignore_errors=True)
    ingest_s = sum(t["ingest"] for t in totals.values())
    ffmpeg_s = sum(t["ffmpeg"] for t in totals.values())
    ffmpeg_cpu = sum(t["ffmpeg_cpu"] for t in totals.values())
    together_ratio = sum(t["together_cpu"] for t in totals.values()) / max(ffmpeg_cpu, 1e-9)
    per_frame = {s: 1e3 * t["detection"] / max(t["frames"], 1) for s, t in totals.items()}
    print(f"ingest: ratio_to_ffmpeg_decode={ingest_s / max(ffmpeg_s, 1e-9):.3f} "
          f"together_cpu_ratio={together_ratio:.3f} "
          f"aruco_ms_per_frame={per_frame.get('aruco', float('nan')):.2f} "
          f"apriltag_ms_per_frame={per_frame.get('apriltag', float('nan')):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
