"""Fuzzing of the C++ bindings: every public function, constructor, method and property
of calibproj._core (and of calibproj._bench) called with bad arguments.

Each callable has a valid baseline call; the bad calls replace one argument at a time
(empty arrays, wrong shapes and dtypes, NaN and infinities, huge and tiny numbers,
non-contiguous arrays, missing dictionary keys, absurd option values, ...), chosen from
a fixed seed within a fixed budget. They run in a child process, which reports each
call before and after making it, so that a segfault, an abort or a hang names the call
instead of killing pytest. Every call must return or raise ValueError, TypeError,
RuntimeError or (for files) OSError with a message.

Run alone (with -s for the summary line):
    PYTHONPATH=python python -m pytest tests/test_fuzz_core.py -q -s
"""

from __future__ import annotations

import copy
import dataclasses
import json
import logging
import math
import os
import selectors
import stat
import subprocess
import sys
import time
import types
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest

from calibproj import _bench, _core

from test_sync import camera_signal  # the tests folder is on sys.path under pytest

SEED = 20250611
# Bad calls per callable at most (the systematic list of a callable is sampled down to
# this many), and in total at least.
MAX_CALLS_PER_CALLABLE = 90
MIN_TOTAL_CALLS = 1400
CALL_TIMEOUT_S = 20.0
CHILD_ADDRESS_SPACE_BYTES = 6 << 30  # an allocation without limit fails instead of swapping
# OSError: a file the system refuses (a name too long, a folder that cannot be made),
# raised as open() raises it; IndexError: a frame or pattern index outside a sequence, as
# a list's index raises it.
ALLOWED_OUTCOMES = {"ok", "ValueError", "TypeError", "RuntimeError", "OSError", "IndexError"}
MODULES = {"_core": _core, "_bench": _bench}
# Where every keyword option meets every absurd value (the others sample them).
EVERY_OPTION = {"_core.ba.bundle_adjust", "_core.registration.Reconstruction", "_core.sync.synchronise",
                "_core.ingest.ingest_camera"}
# No constructor by design (results of a call); the tiny video holds no light code.
BASELINES_THAT_RAISE = {"_core.geometry.Similarity3", "_core.video.VideoInfo", "_core.detect.MarkerFamilyInfo", "_core.ingest.ingest_camera",
                        "_core.ingest.ingest_camera[live]", "_core.check.CameraCheck",
                        "_core.capture.Site", "_core.capture.SiteCamera", "_core.capture.play",
                        "_core.capture.record",
                        "_core.check.CalibrationCheck", "_core.check.CameraVerdict", "_core.formats.CommandFlag", "_core.ba.Result",
                        "_core.registration.PairCandidate", "_core.registration.InitialPairResult", "_core.registration.NextCameraCandidate", "_core.registration.RegisterResult",
                        "_core.registration.AdjustResult", "_core.registration.ReliefTest", "_core.registration.RefineResult", "_core.registration.RunSummary",
                        "_core.formats.CameraPose", "_core.formats.Tracks", "_core.formats.ScaleFit",
                        "_core.selfcal.Result", "_core.selfcal.RefineRequest", "_core.selfcal.LensReport",
                        "_core.selfcal.SelfCalibration", "_core.sync.SyncResult", "_core.sync.CodeLocation",
                        "_core.sync.BandFit", "_core.sync.ReadoutEstimate", "_core.ingest.ScaleRecords",
                        "_core.ingest.MergedCentres", "_core.ingest.FrameClockStats", "_core.ingest.ScaleDriftResult",
                        "_core.Knob",
                        "_core.ba.ManifoldValues", "_core.selfcal.RefinedCalibration"}

# Keyword options of registration.Reconstruction (cpp/bindings/registration.cc).
REGISTRATION_OPTIONS = {
    "model": "coplanar", "loss": "none", "loss_scale_px": 1.0, "homography_threshold_px": 3.0,
    "pnp_threshold_px": 3.0, "ransac_max_iterations": 2000, "ransac_confidence": 0.9999, "seed": 0,
    "min_pair_points": 15, "min_pnp_points": 6, "min_triangulation_angle_deg": 1.0, "min_pair_parallax_deg": 1.0,
    "outlier_threshold_px": 1.0, "outlier_sigma_factor": 3.0, "max_refine_rounds": 5, "view_score_levels": 3,
    "num_threads": 1, "intermediate_ba_iterations": 20, "final_ba_iterations": 100,
    "weak_rotation_sigma_deg": 1.0, "use_projector": True, "min_projector_pnp_points": 4, "estimate_noise": True,
    "projector_sigma_px": 0.1, "error_correlation": 0.005, "shared_error_shift": 0.0, "floor_relief": 0.001,
}


# ---------------------------------------------------------------------------------------
# What is bound: every public callable, by qualified name.



def public_callables() -> list[str]:
    """Qualified names of every public function, class (its constructor), method and
    property of the extension modules, e.g. "_core.ba.bundle_adjust",
    "_core.detect.MarkerDetector.detect"."""
    names: list[str] = []

    def walk(module: types.ModuleType, prefix: str) -> None:
        for name in sorted(dir(module)):
            if name.startswith("_"):
                continue
            value = getattr(module, name)
            qualified = f"{prefix}.{name}"
            if isinstance(value, types.ModuleType):
                walk(value, qualified)
            elif isinstance(value, type) and issubclass(value, BaseException):
                continue  # an exception the bindings raise (_core.formats.InputError)
            elif isinstance(value, type):
                names.append(qualified)
                for attribute, member in sorted(vars(value).items()):
                    if attribute.startswith("_") or isinstance(member, value):
                        continue  # private, or an enum's value
                    if callable(member) or isinstance(member, property):
                        names.append(f"{qualified}.{attribute}")
            elif callable(value):
                names.append(qualified)

    for module_name, module in MODULES.items():
        walk(module, module_name)
    return names


# ---------------------------------------------------------------------------------------
# Bad values, each with a short description for the report.

Mutation = tuple[str, Any]
MISSING = object()  # the argument or key is left out

BAD_FLOATS: list[Mutation] = [
    ("nan", math.nan), ("inf", math.inf), ("-inf", -math.inf), ("0.0", 0.0), ("-1.0", -1.0),
    ("1e-300", 1e-300), ("-1e-300", -1e-300), ("1e300", 1e300), ("-1e300", -1e300), ("2**31 as float", 2.0**31),
]
BAD_INTS: list[Mutation] = [
    ("0", 0), ("-1", -1), ("-2**31", -2**31), ("2**31-1", 2**31 - 1), ("2**31", 2**31), ("2**63", 2**63),
    ("10**6", 10**6), ("10**9", 10**9),
]
# Absurd option values: every option meets all of them.
BAD_OPTIONS: list[Mutation] = [
    ("nan", math.nan), ("inf", math.inf), ("-inf", -math.inf), ("1e300", 1e300), ("-1e300", -1e300),
    ("1e-300", 1e-300), ("-1", -1), ("0", 0), ("2**31-1", 2**31 - 1), ("2**31", 2**31), ("'12'", "12"), ("None", None),
]
BAD_TYPES: list[Mutation] = [
    ("None", None), ("a string", "12"), ("a list", [1.0, 2.0]), ("a dict", {"a": 1}), ("an object", object()),
    ("True", True),
]
BAD_STRINGS: list[Mutation] = [
    ("''", ""), ("'nonsense'", "nonsense"), ("NUL in a string", "a\x00b"), ("100k chars", "x" * 100_000),
    ("non-ASCII", "caméra-\u00e9\u4e2d"), ("an int", 3), ("None", None), ("bytes", b"abc"),
]


def bad_arrays(a: np.ndarray) -> list[Mutation]:
    with np.errstate(all="ignore"):
        return array_mutations(a)


def array_mutations(a: np.ndarray) -> list[Mutation]:
    out: list[Mutation] = [
        ("empty (0, ...)", a[:0] if a.ndim else np.empty(0)), ("empty 1-D", np.empty(0)),
        ("0-d array", np.array(1.0)), ("flattened", a.ravel()), ("extra leading axis", a[None]),
        ("extra trailing axis", a[..., None]), ("as nested lists", a.tolist()),
        ("float32", a.astype(np.float32)), ("int8", a.astype(np.int8)), ("complex", a.astype(np.complex128)),
        ("bool", a.astype(bool)), ("strings", a.astype(str)), ("objects", a.astype(object)),
        ("all NaN", np.full(a.shape, np.nan)), ("all inf", np.full(a.shape, np.inf)),
        ("all 1e300", np.full(a.shape, 1e300)), ("all 1e-300", np.full(a.shape, 1e-300)),
        ("zeros", np.zeros(a.shape, a.dtype)), ("negated", ~a if a.dtype == bool else -a), ("times 1e300", a * 1e300 if a.dtype.kind == "f" else a),
        *BAD_TYPES,
    ]
    if a.ndim >= 1 and a.size:
        flat = a.astype(float).ravel()
        for name, value in [("one NaN", np.nan), ("one inf", np.inf), ("one -inf", -np.inf), ("one 1e300", 1e300)]:
            changed = flat.copy()
            changed[len(changed) // 2] = value
            out.append((name, changed.reshape(a.shape)))
        if a.dtype.kind in "iu":
            for name, value in [("one -1", -1), ("one 2**31-1", 2**31 - 1), ("one -2**31", -2**31), ("one 2**40", 2**40)]:
                changed = a.astype(np.int64).ravel()
                changed[len(changed) // 2] = value
                out.append((name, changed.reshape(a.shape)))
        out += [
            ("one row fewer", a[:-1]), ("one row", a[:1]), ("one row more", np.concatenate([a, a[:1]])),
            ("twice the rows", np.concatenate([a, a])), ("reversed rows (negative stride)", a[::-1]),
            ("non-contiguous rows", np.repeat(a, 2, axis=0)[::2]),
            ("10**6 rows, zero stride", np.broadcast_to(a[:1], (10**6, *a.shape[1:]))),
        ]
    if a.ndim >= 2:
        out += [
            ("one column fewer", a[..., :-1]), ("one column more", np.concatenate([a, a[..., :1]], axis=-1)),
            ("Fortran order", np.asfortranarray(a)), ("transposed", a.T), ("non-contiguous columns",
                                                                              np.repeat(a, 2, axis=-1)[..., ::2]),
        ]
    return out


def deep_list(depth: int = 100_000) -> list:
    out: list = []
    for _ in range(depth):
        out = [out]
    return out


def bad_dicts(d: dict, rng: np.random.Generator) -> list[Mutation]:
    """A nested dict with one entry changed, removed or replaced, at every path."""
    out: list[Mutation] = [("empty dict", {}), ("a list", list(d.values())), ("None", None), ("an int", 3)]
    for path in dict_paths(d):
        where = "/".join(str(p) for p in path)
        value = get_path(d, path)
        if isinstance(path[-1], str):
            out.append((f"{where} removed", set_path(d, path, MISSING)))
        choices = [*BAD_TYPES, ("nan", math.nan), ("1e-300", 1e-300), ("1e300", 1e300), ("-1", -1),
                   ("2**31-1", 2**31 - 1), ("2**31", 2**31), ("[]", []), ("deeply nested list", deep_list(3000))]
        if isinstance(value, list) and value:
            choices += [("a huge list", value * 1000), ("reversed", value[::-1])]
        for name, bad in choices:
            out.append((f"{where}={name}", set_path(d, path, bad)))
    return out


def bad_dataclasses(value: Any, rng: np.random.Generator) -> list[Mutation]:
    """A dataclass (a Calibration, an Intrinsics, ...) with one field replaced by a bad
    value, set past its own checks: the binding must refuse what the class would."""
    out: list[Mutation] = list(BAD_TYPES)
    for field in dataclasses.fields(value):
        for label, bad in bad_values(getattr(value, field.name), rng)[:8]:
            mutated = copy.copy(value)
            object.__setattr__(mutated, field.name, bad)
            out.append((f"{field.name}={label}", mutated))
    return out


def dict_paths(value: Any, prefix: tuple = ()) -> list[tuple]:
    """Paths to every entry of nested dicts, and to the first item of every list."""
    paths = []
    if isinstance(value, dict):
        for key, item in value.items():
            paths.append((*prefix, key))
            paths += dict_paths(item, (*prefix, key))
    elif isinstance(value, list) and value:
        paths.append((*prefix, 0))
        paths += dict_paths(value[0], (*prefix, 0))
    return paths


def get_path(value: Any, path: tuple) -> Any:
    for key in path:
        value = value[key]
    return value


def set_path(value: Any, path: tuple, new: Any) -> Any:
    """A copy of `value` with the entry at `path` replaced by `new` (removed if MISSING)."""
    if not path:
        return new
    copy = dict(value) if isinstance(value, dict) else list(value)
    if len(path) == 1 and new is MISSING:
        del copy[path[0]]
    else:
        copy[path[0]] = set_path(copy[path[0]], path[1:], new)
    return copy


def bad_values(value: Any, rng: np.random.Generator) -> list[Mutation]:
    if isinstance(value, np.ndarray):
        return bad_arrays(value)
    if isinstance(value, _core.detect.CornerRefinement):
        return [("an undefined value 7", _core.detect.CornerRefinement(7)),
                ("an undefined value -1", _core.detect.CornerRefinement(-1)), *BAD_TYPES]
    if isinstance(value, bool):
        return [("None", None), ("'yes'", "yes"), ("2", 2), ("an array", np.ones(2))]
    if isinstance(value, (int, float)):
        return [*BAD_FLOATS, *BAD_INTS, *BAD_TYPES]
    if isinstance(value, str):
        return list(BAD_STRINGS)
    if isinstance(value, dict):
        return bad_dicts(value, rng)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return bad_dataclasses(value, rng)
    if isinstance(value, (list, tuple)) and value:
        return [("empty", type(value)()), ("one item", value[:1]), ("one item more", [*value, value[-1]]),
                ("NaN items", [math.nan] * len(value)), ("huge items", [2**31] * len(value)),
                ("strings", ["a"] * len(value)), ("deeply nested", deep_list(3000)), *BAD_TYPES]
    if isinstance(value, (list, tuple)):
        return [("one item", [1.0]), ("deeply nested", deep_list(3000)), *BAD_TYPES]
    return list(BAD_TYPES)


# ---------------------------------------------------------------------------------------
# Valid baselines.


@dataclasses.dataclass
class Call:
    callable: str  # qualified name (public_callables())
    label: str
    run: Callable[[], Any]
    allowed: frozenset[str] = frozenset(ALLOWED_OUTCOMES)


@dataclasses.dataclass
class Spec:
    """A valid call of one callable: positional arguments by name, keyword arguments,
    and the keyword options it takes besides (name -> default)."""

    args: list[tuple[str, Any]]
    kwargs: dict[str, Any] = dataclasses.field(default_factory=dict)
    options: dict[str, Any] = dataclasses.field(default_factory=dict)


def plane_scene(cameras: int = 4, points: int = 30, seed: int = 5) -> dict[str, np.ndarray]:
    """Cameras 5 units above a floor of points, all seeing every point, in pixels."""
    rng = np.random.default_rng(seed)
    X = np.column_stack([rng.uniform(-1, 1, points), rng.uniform(-1, 1, points), np.zeros(points)])
    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    poses, observed, camera_index, point_index = [], [], [], []
    for c in range(cameras):
        angle = 2 * np.pi * c / cameras
        w = np.array([0.15 * np.cos(angle), 0.15 * np.sin(angle), 0.1 * c])
        t = np.array([0.5 * np.cos(angle), 0.5 * np.sin(angle), 5.0])
        theta = np.linalg.norm(w)
        k = w / theta
        Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        R = np.eye(3) + np.sin(theta) * Kx + (1 - np.cos(theta)) * Kx @ Kx
        x = (K @ (X @ R.T + t).T).T
        observed.append(x[:, :2] / x[:, 2:] + rng.normal(0, 0.3, (points, 2)))
        poses.append(np.concatenate([w, t]))
        camera_index += [c] * points
        point_index += list(range(points))
    return {
        "camera_index": np.array(camera_index, np.int32), "point_index": np.array(point_index, np.int32),
        "observed": np.concatenate(observed), "K": np.stack([K] * cameras), "poses": np.array(poses),
        "points": X, "plane": np.array([0.0, 0.0, 1.0, 0.0]),
        "image_sizes": np.array([[640.0, 480.0]] * cameras),
    }


def write_files(folder: Path) -> dict[str, str]:
    """Files the path arguments point at: a tiny video, an empty file, garbage, a video
    cut in half, a folder."""
    folder.mkdir(parents=True, exist_ok=True)
    video = folder / "tiny.mkv"
    rng = np.random.default_rng(1)
    frames = rng.integers(0, 255, (24, 48, 64), dtype=np.uint8)
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-f", "rawvideo", "-pix_fmt", "gray", "-s", "64x48", "-r", "25",
                    "-i", "-", "-c:v", "ffv1", str(video)], input=frames.tobytes(), check=True)
    (folder / "empty.mp4").write_bytes(b"")
    (folder / "garbage.mp4").write_bytes(rng.integers(0, 255, 5000, dtype=np.uint8).tobytes())
    data = video.read_bytes()
    (folder / "cut.mkv").write_bytes(data[: len(data) // 2])
    (folder / "folder.mp4").mkdir(exist_ok=True)
    (folder / "site.json").write_text(json.dumps({
        "schema": "calibproj.site/1", "sequence": "sequence.json", "projector": {"display": ":4242"},
        "cameras": {"a": {"source": "udp://127.0.0.1:9", "intrinsics": "a.json", "options": {"fifo_size": 1000}},
                    "b": {"source": "tiny.mkv", "intrinsics": "b.json", "exposure_s": 0.01}}}))
    # A room that fails at once: no camera has intrinsics, nothing plays at :4242.
    (folder / "site_fast.json").write_text(json.dumps({
        "schema": "calibproj.site/1", "sequence": "sequence.json", "projector": {"display": ":4242", "timeout_s": 1},
        "cameras": {"a": {"source": "udp://127.0.0.1:9", "intrinsics": "a.json", "open_timeout_s": 0.5},
                    "b": {"source": "tiny.mkv", "intrinsics": "b.json"}},
        "timeouts": {"ready_s": 1, "end_s": 1}}))
    (folder / "recordings").mkdir(exist_ok=True)
    return {name: str(folder / name)
            for name in ("tiny.mkv", "empty.mp4", "garbage.mp4", "cut.mkv", "folder.mp4", "site.json",
                         "site_fast.json", "recordings")}


def bad_paths(files: dict[str, str]) -> list[Mutation]:
    return [("an empty file", files["empty.mp4"]), ("garbage bytes", files["garbage.mp4"]),
            ("a truncated video", files["cut.mkv"]), ("a folder", files["folder.mp4"]),
            ("a missing file", files["tiny.mkv"] + ".missing"), ("/dev/null", "/dev/null"), *BAD_STRINGS]


class Baselines:
    """Valid arguments and receivers for every callable."""

    def __init__(self, files: dict[str, str]) -> None:
        from calibproj.sequence.builder import build_sequence

        self.files = files
        self.scene = plane_scene()
        sequence = build_sequence(arrays=3, scales=(1.0, 2.0), grid=(2, 4), code_degree=4, reference_frames=8)
        self.built_sequence = sequence
        self.core_sequence = _core.ingest.Sequence(sequence)
        self.levels = np.asarray(_core.ingest.light_levels(self.core_sequence))
        self.start_code = sequence.start_code
        self.end_code = sequence.end_code
        light = self.levels.copy()
        light[np.isnan(light)] = 0.2
        rng = np.random.default_rng(7)
        self.rate = 25.0 / sequence.fps
        frames = int(9.0 + self.rate * len(light) + 20)
        self.signal = camera_signal(light, 9.0, self.rate, 0.5, frames, rng)
        self.bands = np.stack([camera_signal(light, 9.0 + 0.02 * b, self.rate, 0.5, frames, rng) for b in range(4)])
        self.image = self.marker_image()
        self.K = np.array([[80.0, 0, 32], [0, 80.0, 24], [0, 0, 1]])
        self.dist = np.array([0.01, -0.002, 0.0, 0.0, 0.0])
        self.intrinsics = _core.formats.CameraIntrinsics("cam", (64, 48), self.K, self.dist)
        self.apriltag_spec = next(s for s in _core.detect.family_specs() if s.startswith("apriltag"))

    def synchronised(self) -> Any:
        return _core.sync.synchronise(self.signal, self.levels, self.start_code, self.end_code, self.rate, "cam")

    def readout(self) -> Any:
        return _core.sync.estimate_readout(self.bands, self.levels, self.start_code, self.end_code,
                                           _core.sync.FrameMap(9.0, self.rate, 0.5))

    def marker_image(self) -> np.ndarray:
        bits = np.asarray(_core.detect.marker_bits("aruco:4X4_50", 3))
        cells = np.pad(bits, 1, constant_values=1)
        image = np.kron(cells, np.ones((10, 10), np.uint8)) * 255
        return np.ascontiguousarray(np.pad(image, 20, constant_values=255).astype(np.uint8))

    def reconstruction(self, state: str = "fresh") -> Any:
        s = self.scene
        r = _core.registration.Reconstruction(s["K"], s["image_sizes"], len(s["points"]), s["camera_index"],
                                              s["point_index"], s["observed"], min_pair_points=8)
        if state in ("initialized", "registered"):
            r.initialize(0, 1)
        if state == "registered":
            r.run()
        return r

    def bundle_adjustment(self, compute_covariance: bool) -> Any:
        call = self.specs()["_core.ba.bundle_adjust"]
        return _core.ba.bundle_adjust(*(value for _, value in call.args),
                                      **{**call.kwargs, "compute_covariance": compute_covariance})

    def self_calibration(self, compute_covariance: bool) -> Any:
        call = self.specs()["_core.selfcal.self_calibrate"]
        return _core.selfcal.self_calibrate(*(value for _, value in call.args),
                                            **{**call.kwargs, "compute_covariance": compute_covariance})

    @staticmethod
    def opened(output: Any) -> Any:
        output.open()
        return output

    @staticmethod
    def provenance_record() -> Any:
        record = _core.formats.ProvenanceRecord()
        record.command = ["calibproj", "calibrate"]
        record.source = _core.formats.ProvenanceInput(path="tracks.json")
        record.videos = [("a", "rtsp://127.0.0.1:8554/a")]
        record.scale = _core.formats.ScaleSource("marker-size:0.1", None, "no marker")
        record.set_options(model="free")
        return record

    def specs(self) -> dict[str, Spec | None]:
        """Valid calls by qualified name (None: a property or a method without arguments
        whose receivers are listed in receivers())."""
        s, f = self.scene, self.files
        ba_args = [("camera_index", s["camera_index"]), ("point_index", s["point_index"]),
                   ("observed", s["observed"]), ("intrinsics", s["K"]), ("poses", s["poses"]),
                   ("points", s["points"]), ("plane", s["plane"])]
        ba_kwargs = {"model": "coplanar", "loss": "huber", "loss_scale": 1.0, "max_iterations": 5,
                     "function_tolerance": 1e-12, "gradient_tolerance": 1e-14, "parameter_tolerance": 1e-12,
                     "num_threads": 1, "linear_solver": "auto", "refine_poses": True, "refine_points": True,
                     "gauge_camera": 0, "scale_camera": -1, "compute_covariance": True, "full_report": False,
                     "cache_rotations": True}
        pose = s["poses"][0]
        x = s["observed"][: len(s["points"])]
        x1 = (x - 320.0) / 500.0
        x2 = (s["observed"][len(s["points"]): 2 * len(s["points"])] - 320.0) / 500.0
        H = np.linalg.lstsq(np.column_stack([x1, np.ones(len(x1))]), np.column_stack([x2, np.ones(len(x2))]),
                            rcond=None)[0].T
        corners = np.array([[[10.0, 10], [50, 10], [50, 50], [10, 50]], [[60.0, 10], [90, 12], [88, 40], [62, 38]]])
        sync_options = {knob.name: knob.default for knob in _core.sync.option_table()}
        ingest_options = {knob.name: knob.default for knob in _core.ingest.option_table()}
        marker_corners = np.array([[20.0, 20], [80, 20], [80, 80], [20, 80]])
        n = 12
        return {
            "_core.ba.bundle_adjust": Spec(ba_args, ba_kwargs),
            "_bench.bundle_adjust_autodiff": Spec(ba_args, ba_kwargs),
            "_core.ba.Result": Spec([]),
            "_core.ba.evaluate_free_cost": Spec([("K", s["K"][0]), ("observed", x[0]), ("pose", pose),
                                                ("point", s["points"][0]), ("want", [True, True])]),
            "_core.ba.evaluate_plane_cost": Spec([("K", s["K"][0]), ("observed", x[0]), ("pose", pose),
                                                 ("plane", s["plane"]), ("ab", np.array([0.1, 0.2])),
                                                 ("want", [True, True, True])]),
            "_core.ba.evaluate_relief_cost": Spec([("K", s["K"][0]), ("observed", x[0]), ("spacing", 0.5),
                                                  ("pose", pose), ("plane", s["plane"]), ("ab", np.array([0.1, 0.2])),
                                                  ("nodes", np.array([0.0, 0.01, -0.01, 0.0])),
                                                  ("want", [True] * 7)]),
            "_core.ba.evaluate_projector_cost": Spec([("projector", np.array([0.1, -0.05])), ("weight", 100.0),
                                                     ("surface_map", np.array([0.4, 0, 0.01, 0, 0.4, 0, 0, 0])),
                                                     ("lens", np.zeros(2)), ("ab", np.array([0.1, 0.2])),
                                                     ("want", [True, True, True])]),
            "_core.ba.evaluate_relief_projector_cost": Spec(
                [("projector", np.array([0.1, -0.05])), ("weight", 100.0),
                 ("surface_map", np.array([0.4, 0, 0.01, 0, 0.4, 0, 0, 0])), ("lens", np.zeros(2)), ("spacing", 0.5),
                 ("ab", np.array([0.1, 0.2])), ("apex", np.array([0.33, 0.0, 0.1])),
                 ("nodes", np.array([0.0, 0.01, -0.01, 0.0])), ("want", [True] * 8)]),
            "_core.selfcal.self_calibrate": Spec(
                [("camera_index", s["camera_index"]), ("point_index", s["point_index"]), ("observed", s["observed"]),
                 ("lenses", np.tile([500.0, 320.0, 240.0, 0, 0, 0, 0, 0], (len(s["poses"]), 1))),
                 ("shapes", np.tile([1.0, 0.0], (len(s["poses"]), 1))), ("refine", [[0, 3]] * len(s["poses"])),
                 ("poses", s["poses"]), ("points", s["points"][:, :2])],
                {"loss": "cauchy", "loss_scale": 2.0, "max_iterations": 5, "num_threads": 1,
                 "compute_covariance": True}),
            "_core.selfcal.Result": Spec([]),
            "_core.selfcal.Result.lens_covariance_of": Spec([("a", 0), ("b", 1)]),
            "_core.selfcal.residual_by_lens": Spec([
                ("K", np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])),
                ("distortion", [-0.2, 0.05, 0.0, 0.0, 0.0]), ("normalised", np.array([0.1, -0.2]))]),
            "_core.selfcal.evaluate_planar_lens_cost": Spec([
                ("shape", np.array([1.0, 0.0])), ("observed", x[0]), ("pose", pose), ("point", s["points"][0, :2]),
                ("lens", np.array([500.0, 320.0, 240.0, -0.1, 0.01, 0, 0, 0]))]),
            "_core.ba.point_on_plane": Spec([("plane", s["plane"]), ("ab", np.array([0.1, 0.2]))]),
            "_core.ba.plane_manifold": Spec([("reference_normal", np.array([0.0, 0, 1])), ("fix_offset", False),
                                            ("x", s["plane"]), ("y", np.array([0.0, 0.1, 1.0, 0.2])),
                                            ("delta", np.array([0.01, 0.02, 0.03]))]),
            "_core.ba.fixed_distance_pose_manifold": Spec([("reference_translation", pose[3:]), ("x", pose),
                                                          ("y", s["poses"][1]), ("delta", np.full(5, 0.01))]),
            "_core.geometry.estimate_similarity": Spec([("src", s["points"]), ("dst", 2.0 * s["points"] + 1.0)]),
            "_core.geometry.triangulate_linear": Spec([
                ("R", np.stack([np.eye(3)] * n)), ("t", np.tile([[0.0, 0, 5], [1.0, 0, 5]], (n // 2, 1))),
                ("rays", np.tile([[0.0, 0.0], [0.2, 0.0]], (n // 2, 1))),
                ("point_index", np.repeat(np.arange(n // 2, dtype=np.int64), 2)), ("num_points", n // 2)]),
            "_core.geometry.estimate_homography": Spec([("x1", x1), ("x2", x2), ("threshold_px", 3.0),
                                                       ("focal1", 500.0), ("focal2", 500.0),
                                                       ("max_iterations", 200), ("seed", 1)]),
            "_core.geometry.decompose_homography": Spec([("H", H), ("x1", x1), ("x2", x2)]),
            "_core.geometry.Similarity3": Spec([]),
            "_core.registration.Reconstruction": Spec(
                [("intrinsics", s["K"]), ("image_sizes", s["image_sizes"]), ("num_points", len(s["points"])),
                 ("camera_index", s["camera_index"]), ("point_index", s["point_index"]),
                 ("observed", s["observed"])], options=REGISTRATION_OPTIONS),
            "_core.registration.Reconstruction.initialize": Spec([("camera1", 0), ("camera2", 1)]),
            "_core.registration.Reconstruction.register_camera": Spec([("camera", 2)]),
            "_core.registration.Reconstruction.add_points": Spec([("camera", 1)]),
            "_core.registration.Reconstruction.adjust": Spec([("final", True)]),
            "_core.registration.Reconstruction.filter_outliers": Spec([("thresholds", [1.0, 1.0, 1.0, 1.0])]),
            "_core.registration.Reconstruction.view_score": Spec([("camera", 1)]),
            "_core.registration.Reconstruction.set_projector": Spec(
                [("pixels", np.tile([960.0, 540.0], (len(s["points"]), 1))), ("width", 1920.0), ("height", 1080.0),
                 ("marker_sides", [24.0, float("nan")] * (len(s["points"]) // 2) + [72.0] * (len(s["points"]) % 2))]),
            "_core.registration.Reconstruction.set_lens_uncertainty": Spec(
                [("camera", 1), ("K", s["K"][1]), ("distortion", [0.01, 0.0, 0.0, 0.0, 0.0]),
                 ("covariance", np.diag([0.25, 0.0, 0.0, 1e-6, 0.0, 0.0, 0.0, 0.0]))]),
            # A fresh reconstruction has no lens: the valid call names none.
            "_core.registration.Reconstruction.set_lens_cross_covariances": Spec(
                [("cameras", []), ("joint", np.zeros((0, 0)))]),
            "_core.registration.Reconstruction.projector_prediction": Spec([("point", 0)]),
            "_core.registration.Reconstruction.projected_plane": Spec([("point", 0)]),
            "_core.registration.Reconstruction.run": Spec([("log", lambda message: None)]),
            "_core.registration.PairCandidate": Spec([]),
            "_core.registration.InitialPairResult": Spec([]),
            "_core.registration.NextCameraCandidate": Spec([]),
            "_core.registration.RegisterResult": Spec([]),
            "_core.registration.AdjustResult": Spec([]),
            "_core.registration.ReliefTest": Spec([]),
            "_core.registration.RefineResult": Spec([]),
            "_core.registration.RunSummary": Spec([]),
            "_core.registration.Reconstruction.calibration": Spec(
                [("camera_names", [f"c{k}" for k in range(len(s["K"]))]), ("point_ids", np.arange(len(s["points"]))),
                 ("left_out", [("x", "no intrinsics file")]), ("model", "coplanar")]),
            "_core.registration.view_score": Spec([("pixels", s["observed"][:30]), ("width", 640.0),
                                                  ("height", 480.0), ("levels", 3)]),
            "_core.detect.family_specs": Spec([]),
            "_core.detect.family_info": Spec([("spec", "aruco:4X4_50")]),
            "_core.detect.MarkerFamilyInfo": Spec([]),
            "_core.detect.marker_bits": Spec([("spec", "aruco:4X4_50"), ("id", 3)]),
            "_core.detect.marker_centres": Spec([("corners", corners)]),
            "_core.detect.check_floor_consistency": Spec([("projector", s["points"][:, :2] * 100),
                                                         ("image", s["observed"][:30]), ("threshold_px", 3.0),
                                                         ("min_points", 8), ("min_share", 0.3),
                                                         ("positions", [i % 10 for i in range(30)]),
                                                         ("min_positions", 3)]),
            "_core.detect.MarkerDetector": Spec([("spec", "aruco:4X4_50"), ("aruco", _core.detect.ArucoOptions()),
                                                ("apriltag", _core.detect.AprilTagOptions())]),
            "_core.detect.MarkerDetector.detect": Spec([("image", self.image)]),
            "_core.detect.ArucoOptions": Spec([]),
            "_core.detect.AprilTagOptions": Spec([]),
            "_core.detect.CornerRefinementOptions": Spec([]),
            "_core.detect.CornerRefinement": Spec([("value", 1)]),
            "_core.video.probe": Spec([("path", f["tiny.mkv"])]),
            "_core.video.VideoInfo": Spec([]),
            "_core.video.frame_timestamps": Spec([("path", f["tiny.mkv"])]),
            "_core.video.SourceOptions": Spec([("live", True), ("format", ""), ("ffmpeg_options", {}),
                                              ("open_timeout_s", 0.5), ("stall_timeout_s", 0.5),
                                              ("record_path", "")]),
            "_core.video.VideoReader": Spec([("path", f["tiny.mkv"]), ("source", None)]),
            "_core.video.StreamWriter": Spec([("url", f["tiny.mkv"] + ".ts"), ("width", 64), ("height", 48),
                                              ("format", "mpegts"), ("key_frame_interval", 15), ("crf", 23),
                                              ("preset", "ultrafast"), ("fps", 30.0)]),
            "_core.video.StreamWriter.write": Spec([("gray", np.zeros((48, 64), dtype=np.uint8)), ("time_s", 0.5)]),
            "_core.capture.Stop": Spec([]),
            "_core.capture.ProjectorOptions": Spec([("display", ":4242"), ("screen", -1), ("video_output", "x11"),
                                                   ("timeout_s", 1.0)]),
            "_core.capture.PresentationLog": Spec([]),
            "_core.capture.Site": Spec([]),
            "_core.capture.SiteCamera": Spec([]),
            "_core.capture.read_site": Spec([("path", f["site.json"])]),
            "_core.capture.site_intrinsics_provenance": Spec([]),
            "_core.capture.CapturePlan": Spec(self.capture_plan_arguments()),
            "_core.capture.CaptureRun": Spec([]),
            "_core.capture.CameraOutcome": Spec([]),
            "_core.capture.Delivery": Spec([]),
            # Every camera fails at once (no intrinsics): "no camera delivers frames".
            "_core.capture.record": Spec([("plan", _core.capture.CapturePlan(**dict(self.capture_plan_arguments()))),
                                          ("abort", None), ("log", None)]),
            "_core.capture.CaptureRun.ingest_result": Spec([("name", "a")]),
            "_core.capture.CaptureRun.write_log": Spec([("path", f["recordings"] + "/capture.json")]),
            # No display answers at :4242: the player fails at once, naming it.
            "_core.capture.play": Spec([("video", f["tiny.mkv"]),
                                        ("options", _core.capture.ProjectorOptions(display=":4242", video_output="x11",
                                                                                   timeout_s=1.0)),
                                        ("stop", None)]),
            "_core.video.frame_period": Spec([("times", [0.0, 0.04, 0.08, 0.16, 0.2])]),
            "_core.video.luma_signal": Spec([("path", f["tiny.mkv"]), ("gamma", 2.2), ("row_step", 2),
                                            ("use_timestamps", True), ("max_frame_gap_s", 2.0)]),
            "_core.sync.option_table": Spec([]),
            "_core.ingest.valid_known_exposure": Spec([("seconds", 0.01)]),
            "_core.ingest.shared_decode_threads": Spec([("decode_threads", 0), ("cameras_at_once", 2)]),
            "_core.ingest.check_options": Spec([("aruco", _core.detect.ArucoOptions()),
                                                ("apriltag", _core.detect.AprilTagOptions())]),
            "_core.ingest.unrefined_lens_changes": Spec([]),
            "_core.registration.option_table": Spec([]),
            "_core.check.option_table": Spec([]),
            "_core.selfcal.option_table": Spec([]),
            "_core.check.CameraCheck": Spec([]),
            "_core.check.check_options": Spec([], {"tolerance_px": 0.5, "min_points": 6}),
            "_core.check.check_camera": Spec(self.camera_check_args(), options={
                knob.name: knob.default for knob in _core.check.option_table()}),
            "_core.registration.check_options": Spec([], dict(REGISTRATION_OPTIONS)),
            "_core.ingest.option_table": Spec([]),
            "_core.sync.synchronise": Spec([("signal", self.signal), ("levels", self.levels),
                                           ("start_code", self.start_code), ("end_code", self.end_code),
                                           ("nominal_rate", self.rate), ("source", "cam")], options=sync_options),
            "_core.sync.locate_code": Spec([("signal", self.signal), ("levels", self.levels),
                                           ("code", self.start_code), ("nominal_rate", self.rate),
                                           ("source", "cam")], options=sync_options),
            "_core.sync.estimate_readout": Spec([("band_signals", self.bands), ("levels", self.levels),
                                                ("start_code", self.start_code), ("end_code", self.end_code),
                                                ("map", _core.sync.FrameMap(9.0, self.rate, 0.5))],
                                               options=sync_options),
            "_core.ingest.Sequence": Spec([(name, np.array(value) if name == "centres" else value)
                                          for name, value in self.built_sequence.parts().items()]),
            "_core.ingest.MarkerSystem": Spec([("spec", "aruco:4X4_50"), ("inverted", True)]),
            "_core.ingest.Pattern": Spec([("array", 1), ("scale_index", 0), ("scale", 1.0), ("marker_side_px", 24.0),
                                          ("first_frame", 3), ("last_frame", 5), ("omitted", [2])]),
            "_core.ingest.Segment": Spec([("kind", "white"), ("first_frame", 0), ("last_frame", 7)]),
            "_core.sync.LightCode": Spec([("bits", [1, 0, 1, 1]), ("frames_per_bit", 3), ("first_frame", 8)]),
            "_core.ingest.Sequence.segment_at": Spec([("frame", 20)]),
            "_core.ingest.Sequence.pattern_index_at": Spec([("frame", 40)]),
            "_core.ingest.Sequence.markers_shown": Spec([("pattern_index", 1)]),
            "_core.ingest.Sequence.save": Spec([("path", f["recordings"] + "/sequence.json")]),
            "_core.ingest.light_levels": Spec([("sequence", self.core_sequence)]),
            "_core.sync.FrameMap": Spec([("offset", 9.0), ("rate", 1.0), ("exposure", 0.5)]),
            "_core.Knob": Spec([]),
            "_core.ba.ManifoldValues": Spec([]),
            **{f"_core.sync.{name}": Spec([]) for name in ("SyncResult", "CodeLocation", "BandFit", "ReadoutEstimate")},
            **{f"_core.ingest.{name}": Spec([]) for name in ("CameraIngestResult", "ScaleRecords", "MergedCentres",
                                                             "ScaleStats", "FrameClockStats", "ScaleDriftResult")},
            "_core.sync.FrameMap.camera_frame": Spec([("projector_time", 3.0)]),
            "_core.sync.FrameMap.projector_time": Spec([("camera_frame", 12.0)]),
            "_core.ingest.lens_tables_map": Spec([("intrinsics", self.intrinsics), ("resolution", (64, 48)),
                                                 ("points", s["observed"][:5] / 10), ("undistort", True)]),
            "_core.ingest.refine_undistorted_corners": Spec([
                ("image", self.image), ("corners", marker_corners), ("intrinsics", self.intrinsics),
                ("cells", 6), ("outward_fraction", 0.45), ("passes", 6)]),
            "_core.ingest.shows_marker": Spec([
                ("image", self.image), ("corners", marker_corners), ("intrinsics", self.intrinsics),
                ("spec", "aruco:4X4_50"), ("id", 3), ("inverted", False)]),
            **self.format_specs(),
            "_core.ingest.ingest_camera": Spec(
                [("video", f["tiny.mkv"]), ("sequence", self.core_sequence), ("intrinsics", self.intrinsics),
                 ("source", "cam"), ("aruco", _core.detect.ArucoOptions()),
                 ("apriltag", _core.detect.AprilTagOptions()), ("progress", lambda decoded, total: None),
                 ("live", None)],
                options=ingest_options),
            # The tiny video read as a live source (FFmpeg's file protocol), recorded.
            "_core.ingest.ingest_camera[live]": Spec(
                [("video", f["tiny.mkv"]), ("sequence", self.core_sequence), ("intrinsics", self.intrinsics),
                 ("source", "cam"), ("aruco", _core.detect.ArucoOptions()),
                 ("apriltag", _core.detect.AprilTagOptions()), ("progress", None),
                 ("live", _core.video.SourceOptions(open_timeout_s=2.0, stall_timeout_s=2.0,
                                                    record_path=str(self.files["tiny.mkv"]) + ".rec.mkv"))]),
        }

    def format_specs(self) -> dict[str, Spec]:
        """The results files, the metric scale and the exports (_core.formats)."""
        from calibproj.formats.calibration import CameraMetrics, Calibration, Plane
        from calibproj.formats.intrinsics import Intrinsics, write_intrinsics
        from calibproj.scale.metric import parse_scale
        from calibproj.sequence.projected import ProjectedMarkers
        from calibproj.formats.tracks import Tracks

        centres = np.stack(np.meshgrid(np.arange(6) * 10.0, np.arange(3) * 10.0), -1).reshape(2, 9, 2)
        points = np.column_stack([centres.reshape(-1, 2) / 100.0, np.zeros(18)])
        poses = {"a": (np.eye(3), np.array([0.0, 0.0, 2.0])), "b": (np.eye(3), np.array([1.0, 0.0, 2.0]))}
        metrics = {name: CameraMetrics(0.3, 0.1, 18, 18, 18, 100, rotation_sigma_deg=0.01, centre_sigma=0.001)
                   for name in poses}
        calibration_args = [("poses", poses), ("failed", {}), ("metrics", metrics), ("points", points),
                            ("point_ids", np.arange(18))]
        calibration = Calibration(*(value for _, value in calibration_args), registration_order=["a", "b"],
                                  planes=[Plane([0.0, 0.0, 1.0], 0.5, 0)])
        markers = ProjectedMarkers(centres, 4.0, (60, 30))
        intrinsics = {name: Intrinsics(name, (64, 48), self.K, self.dist) for name in poses}
        observed = np.tile(centres.reshape(-1, 2), (2, 1))
        tracks = Tracks.from_observations(["a", "b"], np.repeat([0, 1], 18), np.tile(np.arange(18), 2), observed)
        # A second projection's observations: other point ids (a densified sequence's).
        later = Tracks.from_observations(["a", "b"], np.repeat([0, 1], 18), np.tile(np.arange(18, 36), 2), observed)
        folder = Path(self.files["tiny.mkv"]).parent / "formats"
        tracks.write(folder / "valid_tracks.json")
        write_intrinsics(folder / "a.json", intrinsics["a"])
        self.built_sequence.save(folder / "sequence.json")
        # A stored calibration and a check of it (read by the receivers below).
        calibration.save(folder / "results")
        self.results_folder = folder / "results"
        check_args = [("calibration", calibration), ("intrinsics", intrinsics), ("tracks", tracks),
                      ("stored_tracks", tracks), ("unusable", {}), ("not_seen", {})]
        self.check_call = lambda: _core.check.check_calibration(*(value for _, value in check_args))
        self.scale_fit = lambda: _core.formats.scale_factor(calibration, parse_scale("marker-size:1/4=0.1"), markers,
                                                             30.0)
        checked = self.check_call()
        # The same calibration with its poses' covariance, and its uncertainty.json.
        # Camera b's lens refined: its 8 entries follow the poses, correlated with its pose.
        covariance = np.zeros((20, 20))
        covariance[6:12, 6:12] = np.diag([1e-6] * 3 + [1e-5] * 3)
        covariance[12:, 12:] = np.diag([0.25, 0.0, 0.0, 1e-6, 0.0, 0.0, 0.0, 0.0])
        covariance[6, 12] = covariance[12, 6] = 2e-4
        uncertainty_args = [("cameras", ["a", "b"]), ("reference", "a"), ("covariance", covariance),
                            ("noise_px", [0.2, 0.3]), ("lens_block", [-1, 0])]
        self.pose_uncertainty = _core.uncertainty.PoseUncertainty(*(value for _, value in uncertainty_args))
        uncertain = calibration.replace(uncertainty=self.pose_uncertainty)
        _core.uncertainty.write(folder / "results", uncertain, intrinsics)
        volume = np.array([[0.05, 0.05, 0.5], [0.1, 0.2, 0.0]])
        # The self-calibration of the two cameras (its calls and results, and their receivers).
        request = _core.selfcal.RefineRequest.parse(["focal,k1"])
        selfcal_options = {knob.name: knob.default for knob in _core.selfcal.option_table()}
        refine_args = [("tracks", tracks), ("intrinsics", intrinsics), ("calibration", calibration),
                       ("request", request)]
        refine_kwargs = {"options": selfcal_options, "num_threads": 1, "given": intrinsics, "earlier": None,
                         "log": logging.getLogger("fuzz").info}
        self.refinement = lambda: _core.selfcal.refine_lenses(*(value for _, value in refine_args), **refine_kwargs)
        self.request = request
        rounds_args = [("calibration", calibration), ("tracks", tracks), ("intrinsics", intrinsics),
                       ("request", request)]
        rounds_kwargs = {"options": selfcal_options, "num_threads": 1,
                         "register": lambda tracks, intrinsics, lens_covariance: calibration,
                         "log": logging.getLogger("fuzz").info}
        self.refined_calibration = lambda: _core.selfcal.refine_with_registrations(
            *(value for _, value in rounds_args), **rounds_kwargs)
        # The results-folder transaction, on folders of its own.
        outputs = folder / "outputs"
        self.output_folder = lambda: _core.formats.OutputFolder(outputs / "folder", force=True)
        self.output_file = lambda: _core.formats.OutputFile(outputs / "file.json", force=True)
        return {
            "_core.formats.OutputFolder": Spec([("path", outputs / "folder")],
                                               {"force": True, "signature": ["tracks.json"], "min_free_bytes": 1}),
            "_core.formats.OutputFile": Spec([("path", outputs / "file.json")],
                                             {"force": True, "inputs": [str(folder / "results" / "a.json")],
                                              "min_free_bytes": 1}),
            "_core.selfcal.refine_with_registrations": Spec(rounds_args, rounds_kwargs),
            "_core.selfcal.RefinedCalibration": Spec([]),
            "_core.selfcal.refine_lenses": Spec(refine_args, refine_kwargs),
            "_core.selfcal.closed_form_start": Spec(refine_args, {"options": selfcal_options,
                                                                 "log": logging.getLogger("fuzz").info}),
            "_core.selfcal.convert_tracks": Spec([("tracks", tracks), ("given", intrinsics), ("refined", {
                "a": Intrinsics("a", (64, 48), self.K * np.array([[1.1], [1.1], [1.0]]), self.dist)})]),
            "_core.selfcal.refused_cameras": Spec([("request", request), ("intrinsics", intrinsics),
                                                   ("camera_names", ["a", "b"])]),
            "_core.selfcal.write_self_calibration": Spec([("path", folder / "self_calibration.json"),
                                                          ("result", self.refinement()),
                                                          ("given", intrinsics), ("options", selfcal_options)]),
            "_core.selfcal.focal_lengths": Spec([("homographies", [(f"c{k}", np.array(
                [[800.0, 10.0 * k, 5.0], [3.0, 700.0 + 40 * k, -20.0], [0.001 * k, 0.002, 1.0]])) for k in range(5)]),
                ("known", {"c0": 900.0})]),
            "_core.selfcal.check_options": Spec([], options=selfcal_options),
            "_core.selfcal.RefineRequest.parse": Spec([("items", ["focal,k1,k2", "a=none"])]),
            "_core.selfcal.RefineRequest": Spec([]),
            "_core.selfcal.RefineRequest.of": Spec([("camera", "a")]),
            "_core.selfcal.RefineRequest.check_cameras": Spec([("camera_names", ["a", "b"])]),
            "_core.selfcal.LensReport": Spec([]),
            "_core.selfcal.SelfCalibration": Spec([]),
            "_core.selfcal.LensCovariance": Spec([]),
            "_core.selfcal.LensCovariance.among": Spec([("names", ["a", "b"])]),
            "_core.selfcal.LensCovariance.of": Spec([("name", "a")]),
            "_core.uncertainty.PoseUncertainty": Spec(uncertainty_args),
            "_core.uncertainty.PoseUncertainty.named": Spec([("names", ["x", "y"])]),
            "_core.uncertainty.triangulation": Spec([("calibration", uncertain), ("intrinsics", intrinsics),
                                                     ("points", volume), ("noise_px", 0.0)]),
            "_core.uncertainty.projection": Spec([("calibration", uncertain), ("intrinsics", intrinsics),
                                                  ("camera", "b"), ("points", volume)]),
            "_core.uncertainty.write": Spec([("directory", folder), ("calibration", uncertain),
                                             ("intrinsics", intrinsics)]),
            "_core.uncertainty.read_pose_uncertainty": Spec([("directory", folder / "results")]),
            "_core.uncertainty.stored_pose_uncertainty": Spec([("directory", folder / "results"),
                                                               ("calibration", calibration)]),
            "_core.formats.read_calibration": Spec([("directory", folder / "results")]),
            "_core.formats.read_camera_poses": Spec([("path", folder / "results" / "camera_poses.json")]),
            "_core.formats.CameraPoses": Spec([("poses", poses), ("unit", "m"), ("failed", {"c": "not seen"}),
                                               ("source", "estimate.json"), ("weak", ["b"])]),
            "_core.formats.CameraPoses.center": Spec([("name", "a")]),
            "_core.formats.CameraPoses.centers": Spec([("names", ["a", "b"])]),
            "_core.formats.Calibration": Spec(calibration_args, {"registration_order": ["a", "b"],
                                                                 "uncertainty": self.pose_uncertainty}),
            "_core.formats.Calibration.nothing_registered": Spec([("failed", {"a": "no intrinsics file"}),
                                                                  ("model", "free")]),
            "_core.formats.Calibration.load": Spec([("directory", folder / "results")]),
            "_core.formats.Calibration.save": Spec([("directory", folder / "saved")]),
            "_core.formats.Calibration.replace": Spec([], {"unit": "m", "points": points[:3],
                                                           "point_ids": [4, 5, 6]}),
            "_core.formats.Calibration.status": Spec([("name", "b")]),
            "_core.formats.path_as_recorded": Spec([("path", folder / "results" / "tracks.json"),
                                                    ("folder", folder / "saved")]),
            "_core.formats.ProvenanceInput": Spec([], {"path": str(folder / "results"), "given": ""}),
            "_core.formats.ScaleSource": Spec([("measurement", "camera-height:a=2.5")],
                                              {"metres_per_unit": 2.0, "error": ""}),
            "_core.formats.ProvenanceRecord": Spec([]),
            "_core.formats.ProvenanceRecord.set_options": Spec([], {"model": "free", "seed": 3}),
            "_core.formats.ProvenanceRecord.write": Spec([("staging", folder / "results"), ("folder", folder / "saved")],
                                                         {"log": logging.getLogger("fuzz").info}),
            "_core.formats.Calibration.pose": Spec([("name", "a")]),
            "_core.formats.Calibration.center": Spec([("name", "b")]),
            "_core.selfcal.mark_untrusted_lenses_weak": Spec([("result", self.refinement()),
                                                             ("calibration", copy.copy(calibration))]),
            "_core.formats.CommandFlag": Spec([]),
            "_core.formats.command_flag": Spec([("command", "calibrate"), ("name", "--scale")]),
            "_core.formats.command_flags": Spec([]),
            "_core.formats.CameraPose": Spec([]),
            "_core.formats.CameraMetrics": Spec([("mean_px", 0.3), ("std_px", None), ("observations", 18),
                                                 ("inliers", 17), ("track2_observations", 16), ("view_score", 90)],
                                                {"failure": None, "rotation_sigma_deg": 0.01, "weak": True}),
            "_core.formats.Plane": Spec([("normal", [0.0, 0.6, 0.8]), ("offset", 0.5), ("points", 3)]),
            "_core.formats.CameraIntrinsics": Spec([("name", "a"), ("resolution", (64, 48)), ("K", self.K),
                                                    ("dist", self.dist)]),
            "_core.formats.CameraIntrinsics.undistort_points": Spec([("pixels", [[1.0, 2.0], [60.0, 40.0]])]),
            "_core.formats.CameraIntrinsics.distort_points": Spec([("pixels", [[1.0, 2.0], [60.0, 40.0]])]),
            "_core.formats.CameraIntrinsics.normalize": Spec([("pixels", [[1.0, 2.0], [60.0, 40.0]])]),
            "_core.formats.CameraIntrinsics.project_normalized": Spec([("xy", [[0.1, -0.2], [0.0, 0.3]])]),
            "_core.formats.CameraIntrinsics.contains": Spec([("pixels", [[1.0, 2.0], [70.0, 40.0]])],
                                                             {"margin_px": 1.0}),
            "_core.formats.CameraIntrinsics.max_monotonic_radius": Spec([], {"limit": 2.0, "step": 0.01}),
            "_core.formats.CameraIntrinsics.nominal": Spec([("name", "a"), ("width", 64), ("height", 48),
                                                            ("fov_deg", 60.0)]),
            "_core.formats.Tracks": Spec([]),
            "_core.check.CalibrationCheck": Spec([]),
            "_core.check.CameraVerdict": Spec([]),
            "_core.check.check_calibration": Spec(check_args, options={
                knob.name: knob.default for knob in _core.check.option_table()}),
            "_core.check.working_volume": Spec([("calibration", calibration)]),
            "_core.check.predicted_shift_sigma": Spec([
                *[arg for arg in self.camera_check_args() if arg[0] in ("K", "R", "t", "points", "volume", "width",
                                                                         "height")], ("noise_px", 0.1)]),
            "_core.check.repaired": Spec([*check_args[:4], ("check", checked), ("weak_rotation_sigma_deg", 0.05)]),
            "_core.check.write_check": Spec([("path", folder / "check.json"), ("check", checked)]),
            "_core.check.CalibrationCheck.exit_status": Spec([("repaired", True)]),
            "_core.formats.write_calibration": Spec([("directory", folder), ("calibration", calibration)]),
            "_core.formats.write_intrinsics": Spec([("out", folder / "written.json"), ("intrinsics", intrinsics["a"]),
                                                   ("extra", {"board_calibration": {"rms_px": 0.1}})]),
            "_core.formats.read_intrinsics": Spec([("path", str(folder / "a.json")), ("name", "a")]),
            "_core.formats.intrinsics_from_json": Spec([("document", intrinsics["a"].to_json()),
                                                       ("name", "a")]),
            "_core.formats.Tracks.read": Spec([("path", str(folder / "valid_tracks.json"))]),
            "_core.formats.Tracks.from_observations": Spec([
                ("camera_names", ["a", "b"]), ("cameras", np.repeat([0, 1], 18)),
                ("point_ids", np.tile(np.arange(18), 2)), ("xy", observed)], kwargs={"markers_per_array": 9}),
            "_core.formats.Tracks.from_observations[names]": Spec([
                ("camera_names", ["a", "b"]), ("cameras", ["b", "a"]), ("point_ids", [3, 3]),
                ("xy", [[1.0, 2.0], [3.0, 4.0]])]),
            "_core.formats.Tracks.empty": Spec([("camera_names", ["a", "b"])], kwargs={"markers_per_array": 9}),
            "_core.formats.Tracks.write": Spec([("path", folder / "tracks.json")]),
            "_core.formats.Tracks.observations": Spec([("camera", "a")]),
            "_core.formats.Tracks.select": Spec([("observation_mask", np.arange(36) % 3 > 0)],
                                                kwargs={"camera_names": ["b", "c"]}),
            "_core.formats.Tracks.drop_cameras": Spec([("names", ["a"])]),
            "_core.formats.Tracks.with_xy": Spec([("xy", observed + 0.5)]),
            "_core.formats.Tracks.keep_cameras": Spec([("names", ["b"])]),
            "_core.formats.Tracks.drop_points": Spec([("point_ids", [3, 4, 100])]),
            "_core.formats.Tracks.with_min_track_length": Spec([("min_cameras", 2)]),
            "_core.formats.read_sequence": Spec([("path", str(folder / "sequence.json"))]),
            "_core.formats.detect_report_path": Spec([("tracks", folder / "tracks.json")]),
            "_core.formats.intrinsics_files": Spec([("directory", folder)]),
            "_core.formats.video_container": Spec([("path", folder / "tracks.json")]),
            "_core.formats.intrinsics_file": Spec([("directory", folder), ("name", "a")]),
            "_core.formats.with_earlier_observations": Spec([("earlier", folder / "valid_tracks.json"),
                                                            ("tracks", later), ("intrinsics", intrinsics)]),
            "_core.formats.scaled": Spec([("calibration", calibration), ("factor", 2.0)]),
            "_core.formats.parse_scale": Spec([("text", "distance:a,b=2.0")]),
            "_core.formats.ScaleMeasurement": Spec([("kind", "distance"), ("metres", 2.0), ("cameras", ["a", "b"]),
                                                   ("marker", None), ("text", "")]),
            "_core.formats.ScaleFit": Spec([]),
            "_core.formats.check_measurement": Spec([("measurement", parse_scale("marker-size:1/4=0.1")),
                                                    ("camera_names", ["a", "b"]), ("markers", markers)]),
            "_core.formats.scale_factor": Spec([("calibration", calibration),
                                               ("measurement", parse_scale("marker-size:1/4=0.1")),
                                               ("markers", markers), ("radius_sides", 30.0)]),
            "_core.formats.parse_export_formats": Spec([("text", "yaml,colmap")]),
            "_core.formats.ProjectedMarkers": Spec([("centres_px", centres), ("marker_side_px", 4.0),
                                                   ("projector", (60, 30)), ("largest_side_px", np.full((2, 9), 8.0))]),
            "_core.formats.ProjectedMarkers.from_sequence": Spec([("sequence", self.core_sequence)]),
            "_core.formats.ProjectedMarkers.pixels": Spec([("point_ids", np.array([0, 3, 10**9], dtype=np.int64))]),
            "_core.formats.ProjectedMarkers.largest_sides": Spec([
                ("point_ids", np.array([0, 3, 10**9], dtype=np.int64))]),
            "_core.formats.colmap_camera": Spec([("intrinsics", intrinsics["a"])]),
            "_core.formats.quaternion_wxyz": Spec([("R", np.eye(3))]),
            "_core.formats.export": Spec([("calibration", calibration), ("format", "colmap"), ("directory", folder),
                                         ("intrinsics", intrinsics), ("tracks", tracks)]),
        }

    def camera_check_args(self) -> list[tuple[str, Any]]:
        """A camera of the plane scene checked against its own observations."""
        s = self.scene
        w, t = s["poses"][1][:3], s["poses"][1][3:]
        theta = np.linalg.norm(w)
        k = w / theta
        Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        R = np.eye(3) + np.sin(theta) * Kx + (1 - np.cos(theta)) * Kx @ Kx
        observed = s["observed"][s["camera_index"] == 1]
        volume = np.concatenate([s["points"], s["points"] + [0.0, 0.0, 1.0]])
        return [("K", s["K"][1]), ("R", R), ("t", t), ("rotation_sigma", 1e-3), ("centre_sigma", 1e-2),
                ("points", s["points"]), ("observed", observed), ("volume", volume), ("width", 640.0),
                ("height", 480.0), ("reference_points", s["points"]), ("reference_observed", observed)]

    def capture_plan_arguments(self) -> list[tuple[str, Any]]:
        f = self.files
        return [("site", _core.capture.read_site(f["site_fast.json"])), ("sequence_file", "sequence.json"),
                ("sequence", self.core_sequence), ("video", f["tiny.mkv"]), ("intrinsics_folder", ""),
                ("recordings", f["recordings"]), ("aruco", _core.detect.ArucoOptions()),
                ("apriltag", _core.detect.AprilTagOptions()), ("status_interval_s", 2.0)]

    def receivers(self) -> dict[str, dict[str, Callable[[], Any]]]:
        """Objects whose methods and properties are called, by class, in several states."""
        s = self.scene
        return {
            "_core.registration.Reconstruction": {
                state: (lambda state=state: self.reconstruction(state))
                for state in ("fresh", "initialized", "registered")},
            "_core.ba.Result": {
                covariance: (lambda covariance=covariance: self.bundle_adjustment(covariance == "with covariance"))
                for covariance in ("with covariance", "without")},
            # The step results, from a registration in each of its states.
            "_core.registration.PairCandidate": {"ranked": lambda: self.reconstruction().rank_initial_pairs()[0]},
            "_core.registration.InitialPairResult": {
                "initialized": lambda: self.reconstruction().initialize(0, 1),
                "refused": lambda: self.reconstruction("initialized").initialize(0, 1)},
            "_core.registration.NextCameraCandidate": {
                "next": lambda: self.reconstruction("initialized").choose_next_camera(),
                "none": lambda: self.reconstruction("registered").choose_next_camera()},
            "_core.registration.RegisterResult": {
                "registered": lambda: self.reconstruction("initialized").register_camera(2),
                "refused": lambda: self.reconstruction().register_camera(2)},
            "_core.registration.AdjustResult": {"adjusted": lambda: self.reconstruction("initialized").adjust(True)},
            "_core.registration.RefineResult": {"refined": lambda: self.reconstruction("registered").refine()},
            "_core.registration.ReliefTest": {"refined": lambda: self.reconstruction("registered").refine().relief},
            "_core.registration.RunSummary": {"run": lambda: self.reconstruction().run()},
            "_core.geometry.Similarity3": {
                "estimated": lambda: _core.geometry.estimate_similarity(s["points"], s["points"] * 2),
                "degenerate": lambda: _core.geometry.estimate_similarity(s["points"][:1], s["points"][:1])},
            "_core.detect.MarkerDetector": {
                "aruco": lambda: _core.detect.MarkerDetector("aruco:4X4_50"),
                "apriltag": lambda: _core.detect.MarkerDetector(self.apriltag_spec)},
            "_core.detect.ArucoOptions": {"default": _core.detect.ArucoOptions},
            "_core.ingest.Sequence": {"read": lambda: self.core_sequence},
            "_core.ingest.MarkerSystem": {"of the sequence": lambda: self.core_sequence.markers},
            "_core.ingest.Pattern": {"first": lambda: self.core_sequence.patterns[0]},
            "_core.ingest.Segment": {"first": lambda: self.core_sequence.segments[0]},
            "_core.sync.LightCode": {"start": lambda: self.core_sequence.start_code},
            "_core.ingest.CameraIngestResult": {"empty": _core.ingest.CameraIngestResult},
            "_core.Knob": {name: (lambda table=table: table()[0]) for name, table in (
                ("registration", _core.registration.option_table), ("check", _core.check.option_table))},
            "_core.ba.ManifoldValues": {"plane": lambda: _core.ba.plane_manifold(
                np.array([0.0, 0, 1]), False, np.array([0.0, 0, 1, 1]), np.array([0.0, 0, 1, 1]), np.zeros(3))},
            "_core.ingest.ScaleRecords": {"empty": lambda: _core.ingest.CameraIngestResult().records},
            "_core.ingest.MergedCentres": {"empty": lambda: _core.ingest.CameraIngestResult().centres},
            "_core.ingest.FrameClockStats": {"empty": lambda: _core.ingest.CameraIngestResult().timing},
            "_core.ingest.ScaleDriftResult": {"empty": lambda: _core.ingest.CameraIngestResult().scale_drift},
            "_core.ingest.ScaleStats": {"empty": _core.ingest.ScaleStats},
            "_core.sync.FrameMap": {"synced": lambda: self.synchronised().map},
            "_core.sync.SyncResult": {"synced": self.synchronised},
            "_core.sync.CodeLocation": {"start": lambda: self.synchronised().start},
            "_core.sync.ReadoutEstimate": {"estimated": self.readout},
            "_core.sync.BandFit": {"first": lambda: self.readout().bands[0]},
            "_core.check.CameraCheck": {"checked": lambda: _core.check.check_camera(
                *(value for _, value in self.camera_check_args()))},
            "_core.check.CalibrationCheck": {"checked": lambda: self.check_call()},
            "_core.selfcal.RefineRequest": {"parsed": lambda: self.request},
            "_core.selfcal.SelfCalibration": {"refined": lambda: self.refinement()},
            "_core.selfcal.RefinedCalibration": {"refined": lambda: self.refined_calibration()},
            "_core.formats.ProvenanceRecord": {"empty": _core.formats.ProvenanceRecord,
                                               "filled": lambda: self.provenance_record()},
            "_core.formats.ProvenanceInput": {"path": lambda: _core.formats.ProvenanceInput(path="tracks.json")},
            "_core.formats.ScaleSource": {"scaled": lambda: _core.formats.ScaleSource("marker-size:0.1", 2.0)},
            "_core.formats.OutputFolder": {"fresh": lambda: self.output_folder(),
                                           "open": lambda: self.opened(self.output_folder())},
            "_core.formats.OutputFile": {"fresh": lambda: self.output_file(),
                                         "open": lambda: self.opened(self.output_file())},
            "_core.selfcal.LensReport": {
                name: (lambda name=name: self.refinement().reports[name]) for name in ("a", "b")},
            "_core.selfcal.LensCovariance": {"empty": _core.selfcal.LensCovariance,
                                             "refined": lambda: self.refinement().lens_covariance},
            "_core.selfcal.Result": {"solved": lambda: self.self_calibration(True),
                                     "without covariance": lambda: self.self_calibration(False)},
            "_core.check.CameraVerdict": {
                state: (lambda state=state: self.check_call().cameras[state]) for state in ("a", "b")},
            "_core.formats.Calibration": {"read": lambda: _core.formats.read_calibration(self.results_folder)},
            "_core.uncertainty.PoseUncertainty": {"built": lambda: self.pose_uncertainty,
                                                  "numbered": lambda: _core.uncertainty.PoseUncertainty(
                                                      ["0", "1"], "0", self.pose_uncertainty.covariance, [0.2, 0.3])},
            "_core.formats.ScaleFit": {"fitted": lambda: self.scale_fit()},
            "_core.video.VideoInfo": {"probed": lambda: _core.video.probe(self.files["tiny.mkv"])},
            "_core.video.SourceOptions": {"default": _core.video.SourceOptions},
            "_core.video.VideoReader": {"opened": lambda: _core.video.VideoReader(self.files["tiny.mkv"])},
            "_core.video.StreamWriter": {"open": lambda: _core.video.StreamWriter(self.files["tiny.mkv"] + ".ts", 64,
                                                                                 48)},
            "_core.capture.Stop": {"fresh": _core.capture.Stop},
            "_core.capture.ProjectorOptions": {"default": _core.capture.ProjectorOptions},
            "_core.capture.PresentationLog": {"empty": _core.capture.PresentationLog},
            "_core.capture.CaptureRun": {"empty": _core.capture.CaptureRun},
            "_core.capture.CameraOutcome": {"empty": _core.capture.CameraOutcome},
            "_core.capture.Delivery": {"empty": _core.capture.Delivery},
            "_core.capture.Site": {"read": lambda: _core.capture.read_site(self.files["site.json"])},
            "_core.capture.SiteCamera": {
                "read": lambda: _core.capture.read_site(self.files["site.json"]).cameras[0]},
            "_core.detect.MarkerFamilyInfo": {
                family: (lambda family=family: _core.detect.family_info(family))
                for family in ("aruco:4X4_50", "apriltag:tagStandard41h12")},
            "_core.formats.ScaleMeasurement": {
                "parsed": lambda: _core.formats.parse_scale("marker-size:1/4=0.1"),
                "built": lambda: _core.formats.ScaleMeasurement("camera-height", 2.5, ["a"])},
            "_core.formats.ProjectedMarkers": {
                "sized": lambda: _core.formats.ProjectedMarkers(np.zeros((2, 3, 2)), 4.0, (60, 30), np.ones((2, 3))),
                "unsized": lambda: _core.formats.ProjectedMarkers(np.zeros((1, 2, 2)), 1.0, (8, 8))},
            "_core.formats.CommandFlag": {"scale": lambda: _core.formats.command_flag("calibrate", "--scale"),
                                          "switch": lambda: _core.formats.command_flag("detect", "--json")},
            "_core.formats.CameraPose": {"read": lambda: _core.formats.read_calibration(self.results_folder).pose("a")},
            "_core.formats.CameraMetrics": {
                "read": lambda: _core.formats.read_calibration(self.results_folder).metrics["a"]},
            "_core.formats.Plane": {"read": lambda: _core.formats.read_calibration(self.results_folder).planes[0]},
            "_core.formats.CameraPoses": {
                "read": lambda: _core.formats.read_camera_poses(self.results_folder / "camera_poses.json")},
            "_core.formats.CameraIntrinsics": {
                "read": lambda: _core.formats.read_intrinsics(self.results_folder / "a.json", "a")},
            "_core.formats.Tracks": {
                "read": lambda: _core.formats.Tracks.read(self.results_folder.parent / "valid_tracks.json"),
                "empty": lambda: _core.formats.Tracks.empty(["a"])},
            "_core.detect.AprilTagOptions": {"default": _core.detect.AprilTagOptions},
            "_core.detect.CornerRefinementOptions": {"default": _core.detect.CornerRefinementOptions},
            "_core.detect.CornerRefinement": {"edges": lambda: _core.detect.CornerRefinement.edges},
        }

    def use_options(self, cls: str, options: Any) -> Any:
        """Detection with options whose field was set to a bad value."""
        if cls.endswith("CornerRefinementOptions"):
            aruco = _core.detect.ArucoOptions()
            aruco.refinement = options
            return _core.detect.MarkerDetector("aruco:4X4_50", aruco=aruco).detect(self.image)
        if cls.endswith("ArucoOptions"):
            return _core.detect.MarkerDetector("aruco:4X4_50", aruco=options).detect(self.image)
        return _core.detect.MarkerDetector(self.apriltag_spec, apriltag=options).detect(self.image)


# ---------------------------------------------------------------------------------------
# The calls.


def resolve(qualified: str) -> Any:
    module, *rest = qualified.split(".")
    value: Any = MODULES[module]
    for name in rest:
        value = getattr(value, name)
    return value


def spec_calls(qualified: str, name: str, target: Callable[[], Callable], spec: Spec, baselines: Baselines,
               rng: np.random.Generator) -> list[Call]:
    """The valid call, then one argument or option at a time replaced by bad values;
    `name` labels the calls of `qualified`."""

    def call(label: str, args: list[Any], kwargs: dict[str, Any]) -> Call:
        args = [a for a in args if a is not MISSING]
        kwargs = {k: v for k, v in kwargs.items() if v is not MISSING}
        return Call(qualified, f"{name}({label})", lambda: target()(*args, **kwargs))

    values = [v for _, v in spec.args]
    calls = [call("valid", values, spec.kwargs), call("no arguments", [], {}),
             call("an extra argument", [*values, 1.0], spec.kwargs),
             call("an unknown keyword", values, {**spec.kwargs, "no_such_option": 1})]
    for i, (arg, value) in enumerate(spec.args):
        mutations = bad_paths(baselines.files) if arg in ("path", "video") else bad_values(value, rng)
        if arg == "progress":
            mutations = [("raises ValueError", raise_value_error), ("wrong signature", lambda: None),
                         ("not callable", 3)]
        if arg in ("log", "register"):
            mutations = [("raises ValueError", raise_value_error), ("wrong signature", lambda: None),
                         ("not callable", 3), ("None", None)]
        calls.append(call(f"{arg} left out", values[:i], spec.kwargs))
        for label, bad in mutations:
            calls.append(call(f"{arg}={label}", [*values[:i], bad, *values[i + 1:]], spec.kwargs))
    return calls


def option_calls(qualified: str, target: Callable[[], Callable], spec: Spec, every: bool) -> list[Call]:
    """Each keyword option set to each absurd value, the others valid; a NaN or an
    infinity must be refused (ValueError or TypeError). `every`: all options, else those
    of spec.kwargs only."""
    values = [v for _, v in spec.args]
    calls = []
    for key, value in ({**spec.kwargs, **spec.options} if every else spec.kwargs).items():
        mutations = BAD_OPTIONS if not isinstance(value, (bool, str)) else [*BAD_TYPES, ("''", "")]
        for label, bad in mutations:
            kwargs = {**spec.kwargs, key: bad}
            refused = isinstance(bad, float) and not math.isfinite(bad)
            calls.append(Call(qualified, f"{qualified}({key}={label})",
                              lambda kwargs=kwargs: target()(*values, **kwargs),
                              frozenset({"ValueError", "TypeError"}) if refused else frozenset(ALLOWED_OUTCOMES)))
    return calls


def raise_value_error(*args: Any) -> None:
    raise ValueError("raised by the callback")


def sample(calls: list[Call], rng: np.random.Generator, size: int = MAX_CALLS_PER_CALLABLE) -> list[Call]:
    """The first call (the valid one), then at most size - 1 of the others."""
    if len(calls) <= size:
        return calls
    chosen = rng.choice(np.arange(1, len(calls)), size - 1, replace=False)
    return [calls[0], *(calls[i] for i in sorted(chosen))]


def generate_calls(files: dict[str, str]) -> list[Call]:
    """Every bad call, in a fixed order, from SEED."""
    baselines = Baselines(files)
    specs = baselines.specs()
    receivers = baselines.receivers()
    calls: list[Call] = []
    for index, name in enumerate(public_callables()):
        rng = np.random.default_rng([SEED, index])
        owner, _, member = name.rpartition(".")
        own: list[Call] = []
        if owner in receivers:  # a method or property of a bound class
            for state, make in receivers[owner].items():
                own += member_calls(name, owner, member, state, make, specs.get(name), baselines, rng)
        elif name in specs:
            target = lambda name=name: resolve(name)  # noqa: E731
            own = spec_calls(name, name, target, specs[name], baselines, rng)
            options = option_calls(name, target, specs[name], every=name in EVERY_OPTION)
            own = [*sample(own, rng), *(options if name in EVERY_OPTION else sample(options, rng, 30))]
            calls += own
            continue
        else:
            own = [Call(name, f"{name}: no baseline", lambda name=name: missing_baseline(name))]
        calls += sample(own, rng)
    # Second baselines of a callable ("name[variant]"): another path through it.
    for index, variant in enumerate(sorted(key for key in specs if "[" in key)):
        rng = np.random.default_rng([SEED, 1_000_000 + index])
        name = variant.partition("[")[0]
        calls += sample(spec_calls(name, variant, lambda name=name: resolve(name), specs[variant], baselines, rng),
                        rng)
    return calls


def member_calls(name: str, owner: str, member: str, state: str, make: Callable[[], Any], spec: Spec | None,
                 baselines: Baselines, rng: np.random.Generator) -> list[Call]:
    attribute = vars(resolve(owner))[member]
    if isinstance(attribute, property):
        calls = [Call(name, f"{name} of {state}", lambda: getattr(make(), member))]
        if attribute.fset is not None:
            value = getattr(make(), member)
            for label, bad in bad_values(value, rng):
                calls.append(Call(name, f"{name}={label} of {state}, then detection",
                                  lambda bad=bad: set_and_use(make, member, bad, owner, baselines)))
        return calls
    target = lambda: getattr(make(), member)  # noqa: E731 (a fresh receiver per call)
    if spec is None:
        return [Call(name, f"{name}() of {state}", lambda: target()()),
                Call(name, f"{name}(an extra argument) of {state}", lambda: target()(1))]
    calls = spec_calls(name, f"{name} of {state}", target, spec, baselines, rng)
    return calls if state == "fresh" or owner != "_core.registration.Reconstruction" else calls[:1]


def set_and_use(make: Callable[[], Any], member: str, value: Any, owner: str, baselines: Baselines) -> Any:
    receiver = make()
    setattr(receiver, member, value)
    if owner.endswith("Options"):
        return baselines.use_options(owner, receiver)
    return receiver


def missing_baseline(name: str) -> None:
    raise AssertionError(f"{name} has no baseline in tests/test_fuzz_core.py")


# ---------------------------------------------------------------------------------------
# The child process: runs calls from a start index, reporting each on a pipe.


def child_main(folder: str, start: int, stride: int) -> None:
    import faulthandler
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (CHILD_ADDRESS_SPACE_BYTES, CHILD_ADDRESS_SPACE_BYTES))
    faulthandler.enable()
    report = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)  # whatever the library prints goes to stderr, not into the reports
    files = {path.name: str(path) for path in Path(folder).iterdir()}
    calls = generate_calls(files)
    for index in range(start, len(calls), stride):
        report.write(f"start {index}\n")
        try:
            calls[index].run()
            outcome, message = "ok", ""
        except BaseException as error:  # noqa: BLE001 (every outcome is reported)
            # Subclasses count as their base: IsADirectoryError is an OSError, the
            # bindings' InputError a ValueError.
            bases = (OSError, ValueError, TypeError, RuntimeError)
            outcome = next((b.__name__ for b in bases if isinstance(error, b)), type(error).__name__)
            message = str(error)
        report.write(json.dumps({"index": index, "outcome": outcome, "message": message[:300]}) + "\n")
    report.write("end\n")


CHILD = ("import sys; sys.path.insert(0, sys.argv[1]); import test_fuzz_core as t; "
         "t.child_main(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]))")
SHARDS = 2  # children at once, each making every SHARDS-th call


@dataclasses.dataclass
class Outcome:
    index: int
    outcome: str  # "ok", an exception's name, "crash (signal N)", "hang"
    message: str


class LineReader:
    def __init__(self, process: subprocess.Popen) -> None:
        self.process = process
        self.buffer = b""
        self.selector = selectors.DefaultSelector()
        self.selector.register(process.stdout, selectors.EVENT_READ)

    def line(self, timeout: float) -> str | None:
        """The next line; None at the end of the output; TimeoutError after `timeout`."""
        deadline = time.monotonic() + timeout
        while b"\n" not in self.buffer:
            remaining = deadline - time.monotonic()
            if remaining <= 0 or not self.selector.select(remaining):
                raise TimeoutError
            chunk = os.read(self.process.stdout.fileno(), 65536)
            if not chunk:
                return None
            self.buffer += chunk
        line, self.buffer = self.buffer.split(b"\n", 1)
        return line.decode()


class Shard:
    """One child at a time making calls first, first + SHARDS, ...; a child that
    crashes or hangs is replaced by one starting after the call that killed it."""

    def __init__(self, folder: Path, first: int, count: int, log: Path) -> None:
        self.folder, self.count, self.log = folder, count, log
        self.outcomes: list[Outcome] = []
        self.next = first
        self.current: int | None = None
        self.done = first >= count
        self.process: subprocess.Popen | None = None
        if not self.done:
            self.spawn()

    def spawn(self) -> None:
        # In the scratch folder: a bad path given as a plain name ("12") is written there.
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(os.path.abspath(p) for p in sys.path)}
        self.log_offset = self.log.stat().st_size if self.log.exists() else 0
        with open(self.log, "ab") as stderr:
            self.process = subprocess.Popen(
                [sys.executable, "-c", CHILD, str(Path(__file__).parent), str(self.folder), str(self.next),
                 str(SHARDS)], stdout=subprocess.PIPE, stderr=stderr, env=env, cwd=self.folder)
        self.reader = LineReader(self.process)
        self.current = None
        self.deadline = time.monotonic() + 120.0  # generating the calls comes first

    def poll(self) -> None:
        """Reads what the child reported so far (returns within a fraction of a second)."""
        try:
            line = self.reader.line(min(0.2, max(0.0, self.deadline - time.monotonic())))
        except TimeoutError:
            if time.monotonic() < self.deadline:
                return
            self.process.kill()
            self.finish(Outcome(self.current if self.current is not None else self.next, "hang",
                                f"no answer within {CALL_TIMEOUT_S:.0f} s"))
            return
        if line is None or line == "end":
            self.finish(None if line == "end" else Outcome(
                self.current if self.current is not None else self.next,
                f"crash (exit status {self.process.wait()})", self.child_log()))
        elif line.startswith("start "):
            self.current = int(line.split()[1])
            self.deadline = time.monotonic() + CALL_TIMEOUT_S
        else:
            entry = json.loads(line)
            self.outcomes.append(Outcome(entry["index"], entry["outcome"], entry["message"]))
            self.next = entry["index"] + SHARDS
            self.current = None
            self.deadline = time.monotonic() + CALL_TIMEOUT_S

    def finish(self, failure: Outcome | None) -> None:
        self.process.wait()
        self.process.stdout.close()
        if failure is None:
            self.done = True
            return
        if self.current is None and failure.outcome.startswith("crash") and not self.outcomes:
            raise AssertionError(f"a child died before its first call: {self.child_log()}")
        self.outcomes.append(failure)
        self.next = failure.index + SHARDS
        self.done = self.next >= self.count
        if not self.done:
            self.spawn()

    def child_log(self) -> str:
        """What the dead child wrote to stderr (the Python stack of a fatal signal)."""
        with open(self.log, "rb") as log:
            log.seek(self.log_offset)
            lines = log.read().decode(errors="replace").splitlines()
        return " | ".join(line.strip() for line in lines[-8:] if line.strip() and "Extension modules" not in line)


def run_in_children(folder: Path, count: int, log: Path) -> list[Outcome]:
    shards = [Shard(folder, first, count, log) for first in range(SHARDS)]
    while not all(shard.done for shard in shards):
        for shard in shards:
            if not shard.done:
                shard.poll()
    return sorted((o for shard in shards for o in shard.outcomes), key=lambda o: o.index)


# ---------------------------------------------------------------------------------------
# The tests.


def takes_arguments(method: Any) -> bool:
    """Whether a bound method takes arguments besides self (from pybind11's signature)."""
    signature = (method.__doc__ or "").splitlines()[0] if method.__doc__ else ""
    return "*args" in signature or "," in signature.partition("(")[2].partition(")")[0]


def test_every_public_callable_has_a_baseline(tmp_path: Path) -> None:
    files = write_files(tmp_path)
    baselines = Baselines(files)
    covered = set(baselines.specs())
    receivers = baselines.receivers()
    for name in public_callables():
        owner, _, member = name.rpartition(".")
        # A method with arguments needs valid ones to mutate; properties and methods
        # without arguments are called on each of their class's receivers.
        attribute = vars(resolve(owner)).get(member) if owner in receivers else None
        needs_spec = owner not in receivers or (callable(attribute) and takes_arguments(attribute))
        assert name in covered or not needs_spec, f"{name} is bound but not fuzzed: add a baseline"
        assert owner not in receivers or owner in covered, f"{owner}: its constructor needs a baseline"
    stale = {name.partition("[")[0] for name in covered} - set(public_callables())
    assert not stale, f"baselines of callables that are no longer bound: {sorted(stale)}"
    # The valid calls are valid, so that the bad ones test what they claim to.
    for name, spec in baselines.specs().items():
        if name.rpartition(".")[0] in receivers or name in BASELINES_THAT_RAISE:
            continue
        resolve(name.partition("[")[0])(*[v for _, v in spec.args], **spec.kwargs)


def test_bad_calls_neither_crash_nor_hang(tmp_path: Path) -> None:
    files = write_files(tmp_path / "files")
    names = public_callables()
    calls = generate_calls(files)
    assert len(calls) >= MIN_TOTAL_CALLS
    assert {c.callable for c in calls} == set(names)
    started = time.perf_counter()
    outcomes = run_in_children(tmp_path / "files", len(calls), tmp_path / "child.log")
    elapsed = time.perf_counter() - started
    assert len({o.index for o in outcomes}) == len(calls), "some calls were not made"
    bad = [f"{calls[o.index].label}: {o.outcome}: {o.message}" for o in outcomes
           if o.outcome not in calls[o.index].allowed or (o.outcome != "ok" and not o.message.strip())]
    counts: dict[str, int] = {}
    for o in outcomes:
        counts[o.outcome] = counts.get(o.outcome, 0) + 1
    print(f"\nfuzzed {len(calls)} calls of {len(names)} callables in {elapsed:.1f} s: "
          + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    assert not bad, f"{len(bad)} of {len(calls)} bad calls failed:\n" + "\n".join(bad)
    # "/dev/null" is among the bad paths: no writer may have replaced the device.
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
