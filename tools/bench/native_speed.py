"""calibproj-native against the Python command line on the same rendering.

Both run `detect` (videos -> tracks.json) then `calibrate --tracks` (tracks ->
camera_poses.json), on the same videos, one after the other and alternately
(python, native, python, native with --repeats 2), so that both see the same machine
load. The rendering is a folder made by tools/bench/ingest_speed.py (DIR/sequence.json,
DIR/sim/videos, DIR/sim/intrinsics, DIR/sim/truth.json); render one with

  python tools/bench/ingest_speed.py --render-dir RENDERS --systems aruco

and pass RENDERS/aruco. Per command and step it prints the wall time; then the largest
difference between the two commands' camera poses, and the last line

  native: detect_ratio=X calibrate_ratio=Y total_ratio=Z

(native time over Python time, each summed over the repeats).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("rendering", help="rendering folder (sequence.json, sim/videos, sim/intrinsics)")
    parser.add_argument("--native", help="calibproj-native executable (default: next to this Python, else PATH)")
    parser.add_argument("--workers", type=int, default=2, help="cameras processed at once by detect (default 2)")
    parser.add_argument("--repeats", type=int, default=1, help="runs of each command (default 1)")
    return parser.parse_args()


def find_native(given: str | None) -> str:
    candidates = [given] if given else [str(Path(sys.executable).parent / "calibproj-native"),
                                        shutil.which("calibproj-native") or ""]
    for candidate in candidates:
        if candidate and os.access(candidate, os.X_OK):
            return candidate
    sys.exit(f"calibproj-native not found (tried {candidates}); give --native")


def timed(command: list[str]) -> float:
    started = time.perf_counter()
    result = subprocess.run(command, capture_output=True, text=True)
    seconds = time.perf_counter() - started
    if result.returncode != 0:
        sys.exit(f"{' '.join(command)} failed ({result.returncode}):\n{result.stderr[-2000:]}")
    return seconds


def run(program: list[str], rendering: Path, out: Path, workers: int, calibrate_extra: list[str]) -> dict[str, float]:
    sim = rendering / "sim"
    tracks = out / "tracks.json"
    detect = timed([*program, "detect", str(sim / "videos"), "--sequence", str(rendering / "sequence.json"),
                    "--intrinsics", str(sim / "intrinsics"), "--out", str(tracks), "--workers", str(workers),
                    "--no-progress"])
    calibrate = timed([*program, "calibrate", "--tracks", str(tracks), "--intrinsics", str(sim / "intrinsics"),
                       "--out", str(out / "results"), "--force", *calibrate_extra])
    return {"detect": detect, "calibrate": calibrate}


def poses(results: Path) -> dict[str, np.ndarray]:
    document = json.loads((results / "camera_poses.json").read_text())
    out = {}
    for name, camera in document["cameras"].items():
        if "R" in camera:
            out[name] = np.concatenate([np.ravel(camera["R"]), np.ravel(camera["t"])])
    return out


def main() -> None:
    args = parse_args()
    rendering = Path(args.rendering)
    programs = {"python": [sys.executable, "-m", "calibproj"], "native": [find_native(args.native)]}
    # The executable writes no report: neither does the Python command here.
    calibrate_extra = {"python": ["--no-report"], "native": []}
    totals = {name: {"detect": 0.0, "calibrate": 0.0} for name in programs}
    with tempfile.TemporaryDirectory() as scratch:
        for repeat in range(args.repeats):
            for name, program in programs.items():
                out = Path(scratch) / name
                seconds = run(program, rendering, out, args.workers, calibrate_extra[name])
                for step, value in seconds.items():
                    totals[name][step] += value
                print(f"run {repeat + 1} {name:<7} detect {seconds['detect']:7.1f} s  "
                      f"calibrate {seconds['calibrate']:6.1f} s", flush=True)
        python_poses, native_poses = poses(Path(scratch) / "python" / "results"), \
            poses(Path(scratch) / "native" / "results")
        assert python_poses.keys() == native_poses.keys(), "the commands registered different cameras"
        difference = max(float(np.max(np.abs(python_poses[k] - native_poses[k]))) for k in python_poses)
        print(f"cameras registered: {len(python_poses)}; largest pose difference (R, t entries): {difference:.2e}")
    ratio = {step: totals["native"][step] / totals["python"][step] for step in ("detect", "calibrate")}
    total = sum(totals["native"].values()) / sum(totals["python"].values())
    print(f"native: detect_ratio={ratio['detect']:.3f} calibrate_ratio={ratio['calibrate']:.3f} "
          f"total_ratio={total:.3f}")


if __name__ == "__main__":
    main()
