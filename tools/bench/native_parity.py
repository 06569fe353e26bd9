"""calibproj-native against the Python command on a finished demo: the same bytes?

Takes the folder of `calibproj demo --out DEMO` and repeats its calibration with the
standalone executable: `calibproj-native detect` on DEMO/room/videos, then
`calibproj-native calibrate` from those tracks with the demo's metric scale (read from
DEMO/results/provenance.json), its model and every export. Then compares, byte for
byte, every file the executable wrote (camera_poses.json, metrics.json, points.ply,
tracks.json, intrinsics/*.json and the exports) with the demo's, and prints one line
per file, then

  native-parity: identical=K/N

With --refine-intrinsics both tools self-calibrate: `calibproj calibrate --tracks` on
the executable's tracks with the same options is the reference then (the demo itself
calibrated without it).

Run:
  calibproj demo --out DEMO
  python tools/bench/native_parity.py DEMO [--native PATH] [--refine-intrinsics focal,k1,k2]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from native_speed import find_native  # this folder is on sys.path when run as a script

def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("demo", help="folder written by `calibproj demo --out DEMO`")
    parser.add_argument("--native", help="calibproj-native executable (default: next to this Python, else PATH)")
    parser.add_argument("--workers", type=int, default=2, help="cameras processed at once by detect (default 2)")
    parser.add_argument("--refine-intrinsics", action="append", default=[], metavar="[CAMERA=]ENTRIES",
                        help="both tools refine these lens entries (repeatable; default: none, the demo's results "
                             "are the reference)")
    return parser.parse_args()


def run(command: list[str]) -> None:
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode not in (0, 1):  # 1: a camera failed, the others are written
        sys.exit(f"{' '.join(command)} failed ({result.returncode}):\n{result.stderr[-2000:]}")


def demo_settings(results: Path) -> tuple[str, str]:
    """The scale measurement and the registration model the demo calibrated with."""
    provenance = json.loads((results / "provenance.json").read_text())
    scale = (provenance.get("scale") or {}).get("measurement")
    model = json.loads((results / "metrics.json").read_text())["model"]
    if not scale:
        sys.exit(f"{results}: the demo's provenance records no scale measurement")
    return scale, model


def main() -> None:
    args = parse_args()
    demo = Path(args.demo)
    results = demo / "results"
    native = find_native(args.native)
    scale, model = demo_settings(results)
    sequence, intrinsics = demo / "sequence" / "sequence.json", demo / "room" / "intrinsics"
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(scratch) / "native"
        tracks = Path(scratch) / "tracks.json"
        run([native, "detect", str(demo / "room" / "videos"), "--sequence", str(sequence), "--intrinsics",
             str(intrinsics), "--out", str(tracks), "--workers", str(args.workers), "--no-progress"])
        options = ["--tracks", str(tracks), "--intrinsics", str(intrinsics), "--model", model, "--sequence",
                   str(sequence), "--scale", scale, "--export", "yaml,colmap,anipose"]
        options += [flag for entries in args.refine_intrinsics for flag in ("--refine-intrinsics", entries)]
        run([native, "calibrate", *options, "--out", str(out)])
        if args.refine_intrinsics:  # the demo calibrated without: Python on the same tracks is the reference
            results = Path(scratch) / "python"
            run([sys.executable, "-m", "calibproj", "calibrate", *options, "--out", str(results), "--no-report"])
        written = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
        identical = 0
        for name in written:
            same = (results / name).is_file() and (out / name).read_bytes() == (results / name).read_bytes()
            identical += same
            print(f"{name:<26} {'identical' if same else 'DIFFERENT'}")
    print(f"native-parity: identical={identical}/{len(written)}")


if __name__ == "__main__":
    main()
