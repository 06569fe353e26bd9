"""Inputs and mutations shared by the fuzz tests of the two tools (test_fuzz_native.py,
test_fuzz_cli.py): small valid tracks.json, intrinsics and sequence.json documents,
two tiny videos, and mutations of them from a seeded generator (deep nesting, wrong
types, booleans for numbers, NaN and infinity literals, huge and tiny numbers,
duplicate camera names, truncation, byte flips, empty files, ...).
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
from pathlib import Path
from typing import Any

import numpy as np

CAMERAS = 4


# ---------------------------------------------------------------------------------------
# Valid inputs, small.


def tracks_document(rng: np.random.Generator) -> dict:
    """Four cameras above a floor of 30 points, every point seen by every camera."""
    points = np.column_stack([rng.uniform(-1, 1, 30), rng.uniform(-1, 1, 30), np.zeros(30)])
    observations = {}
    for c in range(CAMERAS):
        angle = 2 * np.pi * c / CAMERAS
        t = np.array([0.6 * np.cos(angle), 0.6 * np.sin(angle), 5.0])
        x = points + t
        xy = 500.0 * x[:, :2] / x[:, 2:] + [320.0, 240.0] + rng.normal(0, 0.3, (30, 2))
        observations[f"cam{c}"] = {"point_ids": list(range(30)), "xy": xy.round(4).tolist()}
    return {"schema": "calibproj.tracks/1", "markers_per_array": 8, "undistorted": True,
            "cameras": sorted(observations), "observations": observations}


def intrinsics_document(width: int, height: int, focal: float) -> dict:
    return {"schema": "calibproj.intrinsics/1", "resolution": [width, height],
            "K": [[focal, 0.0, width / 2], [0.0, focal, height / 2], [0.0, 0.0, 1.0]],
            "dist": [0.01, -0.002, 0.0, 0.0, 0.0]}


def write_video(path: Path, rng: np.random.Generator) -> None:
    frames = rng.integers(0, 255, (24, 48, 64), dtype=np.uint8)
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-f", "rawvideo", "-pix_fmt", "gray", "-s", "64x48", "-r", "25",
                    "-i", "-", "-c:v", "ffv1", str(path)], input=frames.tobytes(), check=True)


@dataclasses.dataclass
class Inputs:
    tracks: dict
    calibrate_intrinsics: dict
    sequence: dict
    detect_intrinsics: dict
    videos: Path


def make_inputs(folder: Path, seed: int) -> Inputs:
    """The valid inputs, with two tiny noise videos (cam0, cam1) in ``folder/videos``."""
    from calibproj.sequence.builder import build_sequence

    rng = np.random.default_rng(seed)
    videos = folder / "videos"
    videos.mkdir(parents=True)
    for name in ("cam0", "cam1"):
        write_video(videos / f"{name}.mkv", rng)
    sequence = build_sequence(arrays=3, scales=(1.0, 2.0), grid=(2, 4), code_degree=4, reference_frames=8)
    sequence.save(folder / "sequence_document.json")
    document = json.loads((folder / "sequence_document.json").read_text())
    return Inputs(tracks_document(rng), intrinsics_document(640, 480, 500.0), document,
                  intrinsics_document(64, 48, 80.0), videos)


# ---------------------------------------------------------------------------------------
# Mutations: (label, file bytes, whether the file must be refused).

RAW = "@@raw@@"  # stands for raw JSON text (literals json.dumps does not write)


@dataclasses.dataclass
class Mutation:
    label: str
    data: bytes
    must_fail: bool


def dumps(document: Any, raw: str | None = None) -> bytes:
    text = json.dumps(document, indent=1)
    if raw is not None:
        text = text.replace(json.dumps(RAW), raw, 1)
    return text.encode()


def deep(depth: int, leaf: str = "1") -> str:
    return "[" * depth + leaf + "]" * depth


# Raw JSON values put in place of an entry (after json.dumps, so invalid JSON too).
VALUES = [
    "true", "false", "null", '"text"', '""', "NaN", "Infinity", "-Infinity", "1e400", "-1e400", "1e-300", "-1",
    "0", "2147483648", "9223372036854775808", "1e30", "-1e30", "[]", "{}", "[1, 2]", '{"a": 1}', deep(100_000),
    deep(600), '"' + "x" * 100_000 + '"', "[" + ", ".join(["1.5"] * 100_000) + "]",
]


def paths(value: Any, prefix: tuple = ()) -> list[tuple]:
    """Paths of every dict entry and of the first two items of every list."""
    out = []
    if isinstance(value, dict):
        for key, item in value.items():
            out.append((*prefix, key))
            out += paths(item, (*prefix, key))
    elif isinstance(value, list):
        for index, item in enumerate(value[:2]):
            out.append((*prefix, index))
            out += paths(item, (*prefix, index))
    return out


def replaced(document: Any, path: tuple, new: Any, delete: bool = False) -> Any:
    """A copy of `document` with the entry at `path` replaced (or deleted)."""
    if not path:
        return new
    copy = dict(document) if isinstance(document, dict) else list(document)
    if delete and len(path) == 1:
        del copy[path[0]]
    else:
        copy[path[0]] = replaced(copy[path[0]], path[1:], new, delete)
    return copy


def structural(document: dict, rng: np.random.Generator, count: int) -> list[Mutation]:
    """One entry replaced by a bad value or deleted, at random paths; whether the file
    must be refused depends on the entry, so only crashes, hangs and messages count."""
    candidates = [p for p in paths(document) if p != ("schema",)]
    out = []
    for _ in range(count):
        path = candidates[rng.integers(len(candidates))]
        where = "/".join(map(str, path))
        if isinstance(path[-1], str) and rng.random() < 0.15:
            out.append(Mutation(f"{where} deleted", dumps(replaced(document, path, None, delete=True)), False))
            continue
        value = VALUES[rng.integers(len(VALUES))]
        # NaN, infinity literals and nesting past the reader's limit are not JSON it takes.
        must_fail = value in ("NaN", "Infinity", "-Infinity") or value.startswith("[" * 600)
        out.append(Mutation(f"{where}={value[:20]}", dumps(replaced(document, path, RAW), value), must_fail))
    return out


def byte_level(data: bytes, rng: np.random.Generator, count: int) -> list[Mutation]:
    """Truncations (refused: no JSON object ends early), byte flips, insertions and
    deletions (anything may come out), and files that are no JSON object at all."""
    out = [Mutation("empty file", b"", True), Mutation("only whitespace", b" \n\t\n", True),
           Mutation("binary garbage", rng.integers(0, 256, 2000, dtype=np.uint8).tobytes(), True),
           Mutation("a JSON list", b"[1, 2, 3]", True), Mutation("a JSON number", b"3", True),
           Mutation("nested 100000 deep", deep(100_000).encode(), True),
           Mutation("objects nested 100000 deep", ('{"a":' * 100_000 + "1" + "}" * 100_000).encode(), True),
           Mutation("UTF-8 BOM and NUL", b"\xef\xbb\xbf\x00" + data, True)]
    last_brace = data.rindex(b"}")
    while len(out) < count:
        kind = rng.integers(4)
        if kind == 0:
            cut = int(rng.integers(1, last_brace))
            out.append(Mutation(f"truncated at byte {cut}", data[:cut], True))
        elif kind == 1:
            flipped = bytearray(data)
            for _ in range(int(rng.integers(1, 9))):
                flipped[rng.integers(len(flipped))] ^= 1 << int(rng.integers(8))
            out.append(Mutation("byte flips", bytes(flipped), False))
        elif kind == 2:
            at = int(rng.integers(len(data)))
            junk = bytes(rng.choice(list(b'{}[],:"0123456789.eE-+ntfalsrue\\\x00\xff'), int(rng.integers(1, 6))))
            out.append(Mutation(f"bytes inserted at {at}", data[:at] + junk + data[at:], False))
        else:
            at = int(rng.integers(len(data) - 10))
            out.append(Mutation(f"bytes deleted at {at}", data[:at] + data[at + int(rng.integers(1, 10)):], False))
    return out


def tracks_mutations(tracks: dict, rng: np.random.Generator, budget: int) -> list[Mutation]:
    obs = tracks["observations"]
    first = tracks["cameras"][0]

    def with_first(key: str, value: Any) -> dict:
        return {**tracks, "observations": {**obs, first: {**obs[first], key: value}}}

    targeted = [
        ("duplicate camera name", {**tracks, "cameras": [*tracks["cameras"], first]}),
        ("camera names not strings", {**tracks, "cameras": [1, 2, 3, 4]}),
        ("cameras a string", {**tracks, "cameras": "cam0"}),
        ("observations a list", {**tracks, "observations": []}),
        ("a point id true", with_first("point_ids", [True, *obs[first]["point_ids"][1:]])),
        ("a point id 1.5", with_first("point_ids", [1.5, *obs[first]["point_ids"][1:]])),
        ("a point id 2**63", with_first("point_ids", [2**63, *obs[first]["point_ids"][1:]])),
        ("a point id 1e30", with_first("point_ids", [1e30, *obs[first]["point_ids"][1:]])),
        ("a point id -1", with_first("point_ids", [-1, *obs[first]["point_ids"][1:]])),
        ("a point seen twice", with_first("point_ids", [1, *obs[first]["point_ids"][1:]])),
        ("a pixel with true", with_first("xy", [[True, 1.0], *obs[first]["xy"][1:]])),
        ("a pixel of three values", with_first("xy", [[1.0, 2.0, 3.0], *obs[first]["xy"][1:]])),
        ("fewer pixels than ids", with_first("xy", obs[first]["xy"][1:])),
        ("markers_per_array true", {**tracks, "markers_per_array": True}),
        ("markers_per_array 1e30", {**tracks, "markers_per_array": 1e30}),
        ("markers_per_array -3", {**tracks, "markers_per_array": -3}),
        ("undistorted 1", {**tracks, "undistorted": 1}),
        ("schema 'calibproj.tracks/99'", {**tracks, "schema": "calibproj.tracks/99"}),
    ]
    raw = [("a pixel NaN", "NaN"), ("a pixel Infinity", "Infinity"), ("a pixel 1e400", "1e400"),
           ("a pixel nested 100000 deep", deep(100_000))]
    out = [Mutation(label, dumps(doc), True) for label, doc in targeted]
    out += [Mutation(label, dumps(with_first("xy", [[RAW, 1.0], *obs[first]["xy"][1:]]), value), True)
            for label, value in raw]
    return fill(out, tracks, rng, budget)


def intrinsics_mutations(document: dict, rng: np.random.Generator, budget: int) -> list[Mutation]:
    K = document["K"]
    targeted = [
        ("K with true", {**document, "K": [[True, 0, K[0][2]], K[1], K[2]]}),
        ("K a string", {**document, "K": "500"}),
        ("K of 8 values", {**document, "K": [K[0], K[1], K[2][:2]]}),
        ("K rows of strings", {**document, "K": [["a", "b", "c"], K[1], K[2]]}),
        ("fx 0", {**document, "K": [[0.0, 0, K[0][2]], K[1], K[2]]}),
        ("dist of 3", {**document, "dist": [0.1, 0.2, 0.3]}),
        ("dist with true", {**document, "dist": [True, 0, 0, 0, 0]}),
        ("dist nested with a string", {**document, "dist": [["a"], 0, 0, 0]}),
        ("resolution 1e300", {**document, "resolution": [1e300, 1e300]}),
        ("resolution 2**40", {**document, "resolution": [2**40, 480]}),
        ("resolution true", {**document, "resolution": [True, 480]}),
        ("resolution negative", {**document, "resolution": [-640, 480]}),
        ("resolution of 3", {**document, "resolution": [640, 480, 3]}),
        ("no K", {key: value for key, value in document.items() if key != "K"}),
        ("schema of tracks", {**document, "schema": "calibproj.tracks/1"}),
    ]
    raw = [("K nested 1000000 deep", "K", deep(1_000_000)), ("K nested 100000 deep", "K", deep(100_000)),
           ("K nested 1000 deep", "K", deep(1000)),
           ("K objects nested 100000 deep", "K", '{"a":' * 100_000 + "1" + "}" * 100_000),
           ("dist nested 100000 deep", "dist", deep(100_000)), ("fx NaN", "K", "[[NaN, 0, 1], [0, 1, 1], [0, 0, 1]]"),
           ("dist Infinity", "dist", "[Infinity, 0, 0, 0, 0]"),
           ("fx 1e400", "K", "[[1e400, 0, 1], [0, 1, 1], [0, 0, 1]]"),
           ("resolution nested", "resolution", deep(100_000))]
    out = [Mutation(label, dumps(doc), True) for label, doc in targeted]
    out += [Mutation(label, dumps({**document, key: RAW}, value), True) for label, key, value in raw]
    return fill(out, document, rng, budget)


def sequence_mutations(document: dict, rng: np.random.Generator, budget: int) -> list[Mutation]:
    projector, codes, segments = document["projector"], document["codes"], document["segments"]

    def with_fps(fps: Any) -> dict:
        return {**document, "projector": {**projector, "fps": fps}}

    def with_code(key: str, value: Any) -> dict:
        return {**document, "codes": {**codes, "start": {**codes["start"], key: value}}}

    last = {**segments[-1], "last_frame": 2**31 - 1}
    targeted = [
        ("fps 1e-300", with_fps(1e-300)), ("fps 0", with_fps(0)), ("fps -30", with_fps(-30)),
        ("fps true", with_fps(True)), ("fps 1e300", with_fps(1e300)), ("fps a string", with_fps("30")),
        ("fps 1e-5", with_fps(1e-5)),
        ("projector 2**31 wide", {**document, "projector": {**projector, "resolution": [2**31, 1080]}}),
        ("projector 100000 wide", {**document, "projector": {**projector, "resolution": [100000, 1080]}}),
        ("last frame 2**31-1", {**document, "segments": [*segments[:-1], last]}),
        ("frames_per_bit 2**31-1", with_code("frames_per_bit", 2**31 - 1)),
        ("frames_per_bit 0", with_code("frames_per_bit", 0)),
        ("first_frame -5", with_code("first_frame", -5)),
        ("bits of 2", with_code("bits", [2, 0, 1])), ("bits empty", with_code("bits", [])),
        ("bits true", with_code("bits", [True, False, True])),
        ("no patterns", {**document, "patterns": []}), ("no segments", {**document, "segments": []}),
        ("no centres", {**document, "centres": []}),
        ("unknown marker family", {**document, "markers": {**document["markers"], "spec": "aruco:NOPE"}}),
        ("marker family not a string", {**document, "markers": {**document["markers"], "spec": 3}}),
        ("inverted 1", {**document, "markers": {**document["markers"], "inverted": 1}}),
        ("schema of intrinsics", {**document, "schema": "calibproj.intrinsics/1"}),
        ("frame_count a string", {**document, "frame_count": "lots"}),
        ("frame_count missing", {k: v for k, v in document.items() if k != "frame_count"}),
        ("frame_count off by one", {**document, "frame_count": document["frame_count"] + 1}),
        ("scales true", {**document, "scales": True}),
        ("layout.arrays missing", {**document, "layout": {k: v for k, v in document["layout"].items()
                                                           if k != "arrays"}}),
        ("grid_cells of another family", {**document, "markers": {**document["markers"], "grid_cells": 9}}),
    ]
    raw = [("fps NaN", "NaN"), ("fps 1e400", "1e400"), ("fps -Infinity", "-Infinity"), ("fps nested", deep(100_000))]
    out = [Mutation(label, dumps(doc), True) for label, doc in targeted]
    out += [Mutation(label, dumps(with_fps(RAW), value), True) for label, value in raw]
    out.append(Mutation("centres nested 100000 deep", dumps({**document, "centres": RAW}, deep(100_000)), True))
    return fill(out, document, rng, budget)


def fill(targeted: list[Mutation], document: dict, rng: np.random.Generator, budget: int) -> list[Mutation]:
    """The targeted mutations, then structural and byte-level ones up to the budget."""
    rest = budget - len(targeted)
    return [*targeted, *structural(document, rng, rest // 2), *byte_level(dumps(document), rng, rest - rest // 2)]


def all_mutations(inputs: Inputs, rng: np.random.Generator, budget: dict[str, int]) -> dict[str, list[Mutation]]:
    """Mutations per input format (``tracks``, ``calibrate_intrinsics``, ``sequence``,
    ``detect_intrinsics``), drawn in this order from ``rng``."""
    makers = {"tracks": (tracks_mutations, inputs.tracks),
              "calibrate_intrinsics": (intrinsics_mutations, inputs.calibrate_intrinsics),
              "sequence": (sequence_mutations, inputs.sequence),
              "detect_intrinsics": (intrinsics_mutations, inputs.detect_intrinsics)}
    return {fmt: maker(document, rng, budget[fmt]) for fmt, (maker, document) in makers.items()}


# ---------------------------------------------------------------------------------------
# Runs of either tool (the same command line).


@dataclasses.dataclass
class Run:
    """One invocation: the mutated file among valid ones, and the arguments."""

    fmt: str
    mutation: Mutation
    file: Path
    args: list[str]


def prepare(root: Path, inputs: Inputs, fmt: str, index: int, mutation: Mutation) -> Run:
    """A folder of its own per run, with the mutated file in place of the valid one."""
    folder = root / f"{fmt}-{index:03d}"
    folder.mkdir(parents=True)
    if fmt in ("tracks", "calibrate_intrinsics"):
        intrinsics = folder / "intrinsics"
        intrinsics.mkdir()
        for c in range(CAMERAS):
            (intrinsics / f"cam{c}.json").write_bytes(dumps(inputs.calibrate_intrinsics))
        tracks = folder / "tracks.json"
        tracks.write_bytes(dumps(inputs.tracks))
        target = tracks if fmt == "tracks" else intrinsics / "cam1.json"
        target.write_bytes(mutation.data)
        return Run(fmt, mutation, target, ["calibrate", "--tracks", str(tracks), "--intrinsics", str(intrinsics),
                                           "--out", str(folder / "out")])
    intrinsics = folder / "intrinsics"
    intrinsics.mkdir()
    for name in ("cam0", "cam1"):
        (intrinsics / f"{name}.json").write_bytes(dumps(inputs.detect_intrinsics))
    sequence = folder / "sequence.json"
    sequence.write_bytes(dumps(inputs.sequence))
    target = sequence if fmt == "sequence" else intrinsics / "cam0.json"
    target.write_bytes(mutation.data)
    # Every other run calibrates the videos instead of detecting them: the same ingest.
    out = ["--out", str(folder / "out")] if index % 2 else ["--out", str(folder / "out" / "tracks.json")]
    return Run(fmt, mutation, target, ["calibrate" if index % 2 else "detect", str(inputs.videos), "--sequence",
                                       str(sequence), "--intrinsics", str(intrinsics), *out, "--no-progress",
                                       "--workers", "1"])
