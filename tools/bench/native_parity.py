"""calibproj-native against the Python command on a finished demo: the same bytes?

Takes the folder of `calibproj demo --out DEMO` and repeats its calibration with the
standalone executable: `calibproj-native detect` on DEMO/room/videos, then
`calibproj-native calibrate` from those tracks with the demo's metric scale (read from
DEMO/results/provenance.json), its model and every export. Then compares, byte for
byte, every file the executable wrote (camera_poses.json, metrics.json, points.ply,
tracks.json, intrinsics/*.json and the exports; provenance.json by what it records of
the calibration: version, platform, model, options and scale) with the demo's, and
prints one line per file, then

  native-parity: identical=K/N

With --refine-intrinsics both tools self-calibrate: `calibproj calibrate --tracks` on
the executable's tracks with the same options is the reference then (the demo itself
calibrated without it).

With --room, any rendered room (`calibproj simulate --sequence SEQ`, e.g. the or-table
scene with its table top) takes the demo's place: both tools detect its videos and
calibrate them, each from its own tracks.json, with the metric scale from the first
camera's true height (truth.json) unless --scale is given; tracks.json is compared too.

Run:
  calibproj demo --out DEMO
  python tools/bench/native_parity.py DEMO [--native PATH] [--refine-intrinsics focal,k1,k2]
  calibproj generate --out SEQ --arrays 48 --scales 1,3,6
  calibproj simulate --scene or-table --sequence SEQ/sequence.json --out ROOM
  python tools/bench/native_parity.py --room ROOM --sequence SEQ/sequence.json
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
    parser.add_argument("demo", nargs="?", help="folder written by `calibproj demo --out DEMO`")
    parser.add_argument("--room", type=Path, help="instead of a demo: a room rendered by `calibproj simulate` "
                        "(videos/, intrinsics/, truth.json), detected and calibrated by both tools")
    parser.add_argument("--sequence", type=Path, help="with --room: the sequence.json it was rendered from")
    parser.add_argument("--scale", help="with --room: the --scale measurement (default: the first camera's true "
                        "height in truth.json)")
    parser.add_argument("--model", default="coplanar", help="with --room: the registration model (default coplanar)")
    parser.add_argument("--native", help="calibproj-native executable (default: next to this Python, else PATH)")
    parser.add_argument("--workers", type=int, default=2, help="cameras processed at once by detect (default 2)")
    parser.add_argument("--refine-intrinsics", action="append", default=[], metavar="[CAMERA=]ENTRIES",
                        help="both tools refine these lens entries (repeatable; default: none, the demo's results "
                             "are the reference)")
    args = parser.parse_args()
    if (args.demo is None) == (args.room is None):
        parser.error("give a demo folder or --room (one of them)")
    if args.room is not None and args.sequence is None:
        parser.error("--room needs --sequence")
    return args


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


def room_settings(room: Path) -> str:
    """camera-height of the room's first camera, from its truth."""
    cameras = json.loads((room / "truth.json").read_text())["cameras"]
    name = sorted(cameras)[0]
    return f"camera-height:{name}={cameras[name]['center'][2]!r}"


# What provenance.json says of the calibration itself (its inputs and the command are
# each tool's own here: the executable calibrates its own tracks in a scratch folder).
PROVENANCE_FIELDS = ("calibproj", "platform", "model", "options", "scale")


def same_file(name: str, out: Path, reference: Path) -> bool:
    if not (reference / name).is_file():
        return False
    if name == "provenance.json":
        documents = [json.loads((folder / name).read_text()) for folder in (out, reference)]
        return all(documents[0].get(key) == documents[1].get(key) for key in PROVENANCE_FIELDS)
    return (out / name).read_bytes() == (reference / name).read_bytes()


def compare_files(out: Path, reference: Path) -> None:
    """One line per file the executable wrote, then the summary line (provenance.json is
    compared by PROVENANCE_FIELDS)."""
    written = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    identical = 0
    for name in written:
        same = same_file(name, out, reference)
        identical += same
        print(f"{name:<26} {'identical' if same else 'DIFFERENT'}")
    print(f"native-parity: identical={identical}/{len(written)}")


def main() -> None:
    args = parse_args()
    native = find_native(args.native)
    if args.room is not None:
        videos, intrinsics, sequence = args.room / "videos", args.room / "intrinsics", args.sequence
        scale, model, reference = args.scale or room_settings(args.room), args.model, None
    else:
        demo = Path(args.demo)
        reference = demo / "results"
        scale, model = demo_settings(reference)
        videos, sequence, intrinsics = demo / "room" / "videos", demo / "sequence" / "sequence.json", demo / "room" / "intrinsics"
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(scratch) / "native"
        tracks = Path(scratch) / "tracks.json"
        detect = ["detect", str(videos), "--sequence", str(sequence), "--intrinsics", str(intrinsics),
                  "--workers", str(args.workers), "--no-progress"]
        run([native, *detect, "--out", str(tracks)])
        options = ["--intrinsics", str(intrinsics), "--model", model, "--sequence", str(sequence), "--scale", scale,
                   "--export", "yaml,colmap,anipose"]
        options += [flag for entries in args.refine_intrinsics for flag in ("--refine-intrinsics", entries)]
        run([native, "calibrate", "--tracks", str(tracks), *options, "--out", str(out)])
        python = [sys.executable, "-m", "calibproj"]
        if args.room is not None:  # Python detects and calibrates the room on its own
            python_tracks = Path(scratch) / "python_tracks.json"
            run([*python, *detect, "--out", str(python_tracks)])
            reference = Path(scratch) / "python"
            run([*python, "calibrate", "--tracks", str(python_tracks), *options, "--out", str(reference),
                 "--no-report"])
        elif args.refine_intrinsics:  # the demo calibrated without: Python on the same tracks is the reference
            reference = Path(scratch) / "python"
            run([*python, "calibrate", "--tracks", str(tracks), *options, "--out", str(reference), "--no-report"])
        compare_files(out, reference)


if __name__ == "__main__":
    main()
