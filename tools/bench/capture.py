"""calibproj capture on the virtual operating room against calibrate on the same room
rendered to files, side by side in one run.

For each seed, the ``live`` room (four 640x360 cameras, one zoomed 6x on the table, under
a 960x540 projector) is

- run live (``calibproj.simulate.virtual_room``: Xvfb as the projector's output, each
  camera streaming what it sees of it over loopback UDP on its own clock) and captured
  with ``calibproj.capture.session`` (the projection played there by libmpv); and
- rendered to video files with the same sequence and seed
  (``calibproj.simulate.render``) and calibrated with ``calibproj.pipeline.calibrate``.

Both are compared with the room's truth (Sim(3) alignment, ``calibproj.evaluation.comparison``).
Per seed it prints both RMSEs, when the poses were written after the projection ended,
the frames every camera recorded, and the CPU time of ingesting the recordings (as
files, every camera at once as the capture ingests them) against a plain decode of the
same recordings (``ffmpeg -f null``). The last line:

  capture: poses_after_end_s=.. rot_ratio_vs_files=.. centre_ratio_vs_files=.. ingest_cpu_ratio=..

(the largest poses_after_end_s; the ratios of the mean RMSEs over the seeds; the summed
ingest CPU time over the summed decode CPU time).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import resource
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from calibproj.capture.session import capture
from calibproj.evaluation.comparison import compare
from calibproj.cli.demo_room import LIVE_SCENE, LIVE_SEQUENCE
from calibproj.ingest.videos import ingest
from calibproj.pipeline import calibrate
from calibproj.sequence import generate
from calibproj.simulate.render import simulate_videos
from calibproj.simulate.virtual_room import VirtualRoom, VirtualRoomOptions


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    # Six: the pose RMSE of four cameras spreads 5x over seeds (files: 0.014-0.064 deg),
    # so a ratio of means over three seeds moves by tenths from one run to the next.
    parser.add_argument("--seeds", type=int, default=6, help="rooms run, seeds 0.. (default 6)")
    parser.add_argument("--work-dir", metavar="DIR", help="keep everything here (default: a temporary folder)")
    parser.add_argument("-v", "--verbose", action="store_true", help="the capture's log")
    return parser.parse_args()


def cpu_seconds(who: int) -> float:
    usage = resource.getrusage(who)
    return usage.ru_utime + usage.ru_stime


def decode_cpu(video: Path) -> float:
    """CPU seconds of ``ffmpeg -i VIDEO -f null -``."""
    before = cpu_seconds(resource.RUSAGE_CHILDREN)
    subprocess.run(["ffmpeg", "-v", "error", "-nostdin", "-i", str(video), "-f", "null", "-"], check=True)
    return cpu_seconds(resource.RUSAGE_CHILDREN) - before


def run_live(base: Path, seed: int) -> dict:
    sequence = base / "sequence"
    with VirtualRoom(LIVE_SCENE, base / "room", VirtualRoomOptions(seed=seed)) as room:
        site = room.write_site(base / "site.json", sequence / "sequence.json", sequence / "projection.mp4")
        called = time.monotonic()
        capture(site, base / "live", report=False, progress=False)
        returned = time.monotonic() - called
        if room.errors:
            raise RuntimeError("; ".join(room.errors))
    log = json.loads((base / "live" / "recordings" / "capture.json").read_text())
    ended = log["projection"]["started_s"] + log["projection"]["duration_s"]
    comparison = compare(base / "live" / "camera_poses.json", base / "room" / "truth.json")
    frames = {name: camera["frames"] for name, camera in log["cameras"].items()}
    return {"comparison": comparison, "after_end_s": returned - ended, "frames": frames}


def run_files(base: Path, seed: int) -> object:
    sequence = base / "sequence"
    simulate_videos(LIVE_SCENE, sequence / "sequence.json", base / "files", seed=seed, progress=False)
    calibrate(base / "files" / "videos", base / "files" / "intrinsics", sequence=sequence / "sequence.json",
              out=base / "files_results", report=False, progress=False)
    return compare(base / "files_results" / "camera_poses.json", base / "files" / "truth.json")


def ingest_cpu(base: Path) -> tuple[float, float]:
    """CPU seconds of ingesting the recordings, every camera at once as the capture does
    (as many at a time as there are cores), and of decoding them one by one."""
    videos = {video.stem: video for video in sorted((base / "live" / "recordings").glob("*.mkv"))}
    before = cpu_seconds(resource.RUSAGE_SELF)
    ingest(videos, base / "sequence" / "sequence.json", base / "room" / "intrinsics", workers=os.cpu_count() or 1,
           progress=False)
    ingested = cpu_seconds(resource.RUSAGE_SELF) - before
    return ingested, sum(decode_cpu(video) for video in videos.values())


def main() -> int:
    args = parse_args()
    logging.basicConfig(level=logging.INFO if args.verbose else logging.ERROR, format="%(message)s")
    work = Path(args.work_dir) if args.work_dir else Path(tempfile.mkdtemp(prefix="calibproj-capture-"))
    live_rot, live_centre, file_rot, file_centre, after_end = [], [], [], [], []
    cpu = np.zeros(2)
    try:
        for seed in range(args.seeds):
            base = work / f"seed{seed}"
            shutil.rmtree(base, ignore_errors=True)
            generate(base / "sequence", **LIVE_SEQUENCE)
            live = run_live(base, seed)
            files = run_files(base, seed)
            cpu += ingest_cpu(base)
            ours = live["comparison"]
            live_rot.append(ours.rotation_rmse_deg)
            live_centre.append(ours.translation_rmse_pct)
            file_rot.append(files.rotation_rmse_deg)
            file_centre.append(files.translation_rmse_pct)
            after_end.append(live["after_end_s"])
            print(f"seed {seed}: live rotation {ours.rotation_rmse_deg:.4f} deg centre {ours.translation_rmse_pct:.4f} % "
                  f"({len(ours.registered)} registered, missing {ours.missing or 'none'}); files rotation "
                  f"{files.rotation_rmse_deg:.4f} deg centre {files.translation_rmse_pct:.4f} % "
                  f"({len(files.registered)} registered); poses {live['after_end_s']:.1f} s after the end; "
                  f"frames {live['frames']}", flush=True)
    finally:
        if not args.work_dir:
            shutil.rmtree(work, ignore_errors=True)
    print(f"capture: poses_after_end_s={max(after_end):.1f} "
          f"rot_ratio_vs_files={np.mean(live_rot) / np.mean(file_rot):.2f} "
          f"centre_ratio_vs_files={np.mean(live_centre) / np.mean(file_centre):.2f} "
          f"ingest_cpu_ratio={cpu[0] / cpu[1]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
