"""Fuzzing of the Python command line's input files: the mutations of test_fuzz_native.py
(tests/fuzz_inputs.py) fed through ``calibproj calibrate --tracks`` (tracks.json and
intrinsics files) and ``calibproj detect`` (sequence.json and intrinsics files, two tiny
videos), and mutated results through ``calibproj evaluate`` (its evaluation tracks, a
results folder's metrics.json and points.ply, the latter two with --save), ``calibproj check``
(its check tracks with --out, a results folder's metrics.json and points.ply) and
``calibproj compare`` (a camera_poses.json).

Every run must end by itself within RUN_TIMEOUT_S with exit status 0, 1 or 2, without a
traceback or an "internal error"; status 2 (a bad input) with exactly one error line
naming the mutated file. The mutations that break the format must give status 2, except
a camera's intrinsics file: that camera fails (status 1, the file named), the others go
on.

The commands run in-process (``calibproj.cli.main.main``) in WORKERS worker processes, each
started once (this file run as a script with --serve): Python with numpy and OpenCV
starts too slowly for a process per file. A worker that does not answer in time is
killed (a hang) and replaced; one that dies is a crash.

Run alone (with -s for the summary line):
    PYTHONPATH=python python -m pytest tests/test_fuzz_cli.py -q -s
"""

from __future__ import annotations

import collections
import json
import os
import queue
import select
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import calibproj
# The tests folder is on sys.path under pytest.
from fuzz_inputs import (RAW, Inputs, Mutation, Run, all_mutations, deep, dumps, fill, intrinsics_mutations,
                         make_inputs, prepare, tracks_mutations)

SEED = 20250613  # another seed than the native tool's fuzzing: other files
RUN_TIMEOUT_S = 20.0
STARTUP_TIMEOUT_S = 60.0
WORKERS = 2
# Mutated files per input format.
BUDGET = {"tracks": 200, "calibrate_intrinsics": 120, "sequence": 200, "detect_intrinsics": 80,
          "eval_tracks": 80, "evaluate_intrinsics": 60, "camera_poses": 100, "metrics": 80, "points": 60,
          "check_tracks": 60, "check_metrics": 30, "check_points": 30}
MIN_FILES = 500
MAX_ERROR_LINE = 1000  # characters: one line a person reads
# A camera's own file: a bad one fails that camera, not the run.
PER_CAMERA = ("calibrate_intrinsics", "detect_intrinsics", "evaluate_intrinsics")


# ---------------------------------------------------------------------------------------
# Workers: calibproj.cli.main.main in a process of its own, one command line per request.


def serve() -> None:
    """The worker's loop: a JSON list of arguments per line on stdin, a JSON answer
    ``{"status", "stderr"}`` per line on the original stdout. The command's stdout goes
    to /dev/null and its stderr (file descriptor 2, so the log and anything the C++
    core writes) into a file read back for the answer."""
    from calibproj.cli.main import main
    from calibproj import pipeline
    from calibproj.evaluation import independent as evaluation
    from calibproj.ingest import videos as ingest  # noqa: F401  (imported once, before the first request)

    answers = os.fdopen(os.dup(1), "w")
    os.dup2(os.open(os.devnull, os.O_WRONLY), 1)
    answers.write(json.dumps({"ready": True}) + "\n")
    answers.flush()
    for line in sys.stdin:
        with tempfile.TemporaryFile() as captured:
            status = run_captured(main, json.loads(line), captured.fileno())
            captured.seek(0)
            stderr = captured.read().decode(errors="replace")
        answers.write(json.dumps({"status": status, "stderr": stderr}) + "\n")
        answers.flush()


def run_captured(main: Any, argv: list[str], stderr_fd: int) -> Any:
    saved = os.dup(2)
    os.dup2(stderr_fd, 2)
    try:
        return main(argv)
    except SystemExit as exit:  # argparse
        return exit.code
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(saved, 2)
        os.close(saved)


class Worker:
    """One worker process; replaced when it hangs or dies."""

    def __init__(self) -> None:
        self.process: subprocess.Popen | None = None

    def start(self) -> None:
        package_parent = str(Path(calibproj.__file__).resolve().parents[1])
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [package_parent,
                                                                          os.environ.get("PYTHONPATH")]))}
        self.process = subprocess.Popen([sys.executable, __file__, "--serve"], stdin=subprocess.PIPE,
                                        stdout=subprocess.PIPE, text=True, env=env)
        ready = self._answer(STARTUP_TIMEOUT_S)
        if not isinstance(ready, dict) or not ready.get("ready"):
            raise RuntimeError(f"the fuzz worker did not start: {ready}")

    def call(self, argv: list[str]) -> dict[str, Any]:
        """``{"status", "stderr"}``, or ``{"problem"}`` for a hang or a crash."""
        if self.process is None:
            self.start()
        self.process.stdin.write(json.dumps(argv) + "\n")
        self.process.stdin.flush()
        answer = self._answer(RUN_TIMEOUT_S)
        if isinstance(answer, dict):
            return answer
        return {"problem": answer}

    def _answer(self, timeout: float) -> dict[str, Any] | str:
        ready, _, _ = select.select([self.process.stdout], [], [], timeout)
        if not ready:
            self.stop()
            return f"hang (no answer within {timeout:.0f} s)"
        line = self.process.stdout.readline()
        if not line:
            status = self.process.wait()
            self.stop()
            return f"the worker died (status {status})"
        return json.loads(line)

    def stop(self) -> None:
        if self.process is None:
            return
        self.process.kill()
        self.process.wait()
        for pipe in (self.process.stdin, self.process.stdout):
            try:
                pipe.close()
            except BrokenPipeError:  # a request the dead worker did not read
                pass
        self.process = None


def run_all(runs: list[Run]) -> list[dict[str, Any]]:
    """Every run's answer, in order, from WORKERS workers taking runs from one queue."""
    todo: queue.Queue = queue.Queue()
    for index, run in enumerate(runs):
        todo.put((index, run))
    answers: list[dict[str, Any]] = [{} for _ in runs]

    def work() -> None:
        worker = Worker()
        try:
            while True:
                try:
                    index, run = todo.get_nowait()
                except queue.Empty:
                    return
                answers[index] = worker.call(run.args)
        finally:
            worker.stop()

    threads = [threading.Thread(target=work) for _ in range(WORKERS)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return answers


# ---------------------------------------------------------------------------------------
# Results to evaluate and compare, and their mutations.


def results_mutations(results: Path, rng: np.random.Generator) -> dict[str, list[Mutation]]:
    """Mutations of the files of a results folder, per format."""
    def read(name: str) -> dict:
        return json.loads((results / name).read_text())

    return {"eval_tracks": tracks_mutations(read("tracks.json"), rng, BUDGET["eval_tracks"]),
            "evaluate_intrinsics": intrinsics_mutations(read("intrinsics/cam1.json"), rng,
                                                        BUDGET["evaluate_intrinsics"]),
            "camera_poses": poses_mutations(read("camera_poses.json"), rng, BUDGET["camera_poses"]),
            "metrics": metrics_mutations(read("metrics.json"), rng, BUDGET["metrics"]),
            "points": points_mutations((results / "points.ply").read_bytes(), rng, BUDGET["points"]),
            "check_tracks": tracks_mutations(read("tracks.json"), rng, BUDGET["check_tracks"]),
            "check_metrics": metrics_mutations(read("metrics.json"), rng, BUDGET["check_metrics"]),
            "check_points": points_mutations((results / "points.ply").read_bytes(), rng, BUDGET["check_points"])}


def points_mutations(data: bytes, rng: np.random.Generator, budget: int) -> list[Mutation]:
    """A results folder's points.ply: its header and vertices broken on purpose, then
    truncations (refused when a whole vertex is lost), byte flips and deletions."""
    text = data.decode()
    header, _, body = text.partition("end_header\n")
    rows = body.splitlines()
    first = rows[0].split()

    def with_rows(new_rows: list[str], new_header: str = header) -> bytes:
        return (new_header + "end_header\n" + "\n".join(new_rows) + "\n").encode()

    targeted = [
        Mutation("empty file", b"", True),
        Mutation("binary garbage", rng.integers(0, 256, 2000, np.uint8).tobytes(), True),
        Mutation("latin-1 byte in a vertex", with_rows([rows[0] + " \xe9", *rows[1:]]).replace(b"\xc3\xa9", b"\xe9"),
                 True),
        Mutation("no end_header", header.encode() + body.encode(), True),
        Mutation("no element vertex", with_rows(rows, header.replace("element vertex", "element face")), True),
        Mutation("vertex count a word", with_rows(rows, header.replace(f"element vertex {len(rows)}",
                                                                          "element vertex many")), True),
        Mutation("vertex count -1", with_rows(rows, header.replace(f"element vertex {len(rows)}",
                                                                      "element vertex -1")), True),
        Mutation("one vertex more declared",
                 with_rows(rows, header.replace(f"element vertex {len(rows)}", f"element vertex {len(rows) + 1}")),
                 True),
        Mutation("a vertex of 3 numbers", with_rows([" ".join(first[:3]), *rows[1:]]), True),
        Mutation("a vertex of 5 numbers", with_rows([rows[0] + " 7", *rows[1:]]), True),
        Mutation("a coordinate a word", with_rows([" ".join(["x", *first[1:]]), *rows[1:]]), True),
        Mutation("a coordinate NaN", with_rows([" ".join(["nan", *first[1:]]), *rows[1:]]), True),
        Mutation("a coordinate inf", with_rows([" ".join([*first[:2], "inf", first[3]]), *rows[1:]]), True),
        Mutation("an id 1.5", with_rows([" ".join([*first[:3], "1.5"]), *rows[1:]]), True),
        Mutation("an id -3", with_rows([" ".join([*first[:3], "-3"]), *rows[1:]]), True),
        Mutation("an id 1e300", with_rows([" ".join([*first[:3], "1e300"]), *rows[1:]]), True),
        Mutation("an id twice", with_rows([rows[0], rows[0], *rows[2:]]), True),
        Mutation("schema of another file", data.replace(b"comment schema ", b"comment schema x"), True),
    ]
    last_row = len(data) - len(rows[-1]) - 1
    out = list(targeted)
    while len(out) < budget:
        kind = rng.integers(3)
        if kind == 0:
            cut = int(rng.integers(1, len(data) - 1))
            out.append(Mutation(f"truncated at byte {cut}", data[:cut], cut < last_row))
        elif kind == 1:
            flipped = bytearray(data)
            for _ in range(int(rng.integers(1, 9))):
                flipped[rng.integers(len(flipped))] ^= 1 << int(rng.integers(8))
            out.append(Mutation("byte flips", bytes(flipped), False))
        else:
            at = int(rng.integers(len(data) - 10))
            out.append(Mutation(f"bytes deleted at {at}", data[:at] + data[at + int(rng.integers(1, 10)):], False))
    return out


def poses_mutations(document: dict, rng: np.random.Generator, budget: int) -> list[Mutation]:
    cameras = document["cameras"]
    first = sorted(cameras)[0]
    entry = cameras[first]
    R, t = entry["R"], entry["t"]

    def with_first(key: str, value: Any) -> dict:
        return {**document, "cameras": {**cameras, first: {**entry, key: value}}}

    targeted = [
        ("R with true", with_first("R", [[True, *R[0][1:]], R[1], R[2]])),
        ("R scaled by 2", with_first("R", [[2 * v for v in row] for row in R])),
        ("R of 8 values", with_first("R", [R[0], R[1], R[2][:2]])),
        ("R rows of strings", with_first("R", [["a", "b", "c"], R[1], R[2]])),
        ("t of 2", with_first("t", t[:2])), ("t with false", with_first("t", [False, *t[1:]])),
        ("t a string", with_first("t", "0 0 0")), ("t of strings", with_first("t", ["1", "2", "3"])),
        ("center with true", with_first("center", [True, 0, 0])),
        ("weak 'yes'", with_first("weak", "yes")), ("rotation sigma true", with_first("rotation_sigma_deg", True)),
        ("a camera a number", {**document, "cameras": {**cameras, first: 3}}),
        ("cameras a list", {**document, "cameras": []}), ("failed a list", {**document, "failed": [first]}),
        ("a failure reason a number", {**document, "failed": {"camX": 3}}),
        ("unit furlong", {**document, "unit": "furlong"}), ("unit true", {**document, "unit": True}),
        ("frame camera", {**document, "frame": "camera"}),
        ("schema 'calibproj.camera_poses/99'", {**document, "schema": "calibproj.camera_poses/99"}),
        ("schema of tracks", {**document, "schema": "calibproj.tracks/1"}),
    ]
    raw = [("t NaN", "t", "[NaN, 0, 0]"), ("t 1e400", "t", "[1e400, 0, 0]"),
           ("R nested 100000 deep", "R", deep(100_000)), ("t a 5000-digit integer", "t", "[" + "7" * 5000 + ", 0, 0]")]
    out = [Mutation(label, dumps(doc), True) for label, doc in targeted]
    out += [Mutation(label, dumps(with_first(key, RAW), value), True) for label, key, value in raw]
    return fill(out, document, rng, budget)


def metrics_mutations(document: dict, rng: np.random.Generator, budget: int) -> list[Mutation]:
    cameras = document["cameras"]
    first = sorted(cameras)[0]
    entry = cameras[first]

    def with_first(key: str, value: Any) -> dict:
        return {**document, "cameras": {**cameras, first: {**entry, key: value}}}

    targeted = [
        ("mean_px true", with_first("mean_px", True)), ("mean_px a string", with_first("mean_px", "0.3")),
        ("inliers 1.5", with_first("inliers", 1.5)), ("inliers -1", with_first("inliers", -1)),
        ("observations true", with_first("observations", True)), ("weak 1", with_first("weak", 1)),
        ("failure a number", with_first("failure", 3)), ("an unknown field", with_first("colour", "red")),
        ("a field missing", {**document, "cameras": {**cameras, first: {k: v for k, v in entry.items()
                                                                          if k != "inliers"}}}),
        ("a camera a list", {**document, "cameras": {**cameras, first: [1, 2]}}),
        ("cameras a list", {**document, "cameras": []}), ("floor_rms true", {**document, "floor_rms": True}),
        ("floor_rms a string", {**document, "floor_rms": "0.1"}),
        ("registration_order a string", {**document, "registration_order": "cam0"}),
        ("model 3", {**document, "model": 3}), ("model 'bent'", {**document, "model": "bent"}),
        ("schema of camera poses", {**document, "schema": "calibproj.camera_poses/1"}),
    ]
    raw = [("floor_rms NaN", "NaN"), ("floor_rms -Infinity", "-Infinity"), ("floor_rms nested", deep(100_000))]
    out = [Mutation(label, dumps(doc), True) for label, doc in targeted]
    out += [Mutation(label, dumps({**document, "floor_rms": RAW}, value), True) for label, value in raw]
    return fill(out, document, rng, budget)


def prepare_results_run(root: Path, results: Path, fmt: str, index: int, mutation: Mutation) -> Run:
    """evaluate (mutated evaluation tracks, a copy of the results' intrinsics with one
    file mutated, or a copy of the results folder with a mutated metrics.json or
    points.ply) or compare
    (a mutated camera_poses.json with the valid one)."""
    folder = root / f"{fmt}-{index:03d}"
    folder.mkdir(parents=True)
    if fmt == "evaluate_intrinsics":
        intrinsics = folder / "intrinsics"
        shutil.copytree(results / "intrinsics", intrinsics)
        target = intrinsics / "cam1.json"
        target.write_bytes(mutation.data)
        return Run(fmt, mutation, target, ["evaluate", str(results), "--tracks", str(results / "tracks.json"),
                                           "--intrinsics", str(intrinsics)])
    if fmt in ("check_metrics", "check_points"):
        copy = folder / "results"
        shutil.copytree(results, copy)
        target = copy / ("metrics.json" if fmt == "check_metrics" else "points.ply")
        target.write_bytes(mutation.data)
        return Run(fmt, mutation, target, ["check", str(copy), "--tracks", str(results / "tracks.json")])
    if fmt == "check_tracks":
        target = folder / "check_tracks.json"
        target.write_bytes(mutation.data)
        return Run(fmt, mutation, target, ["check", str(results), "--tracks", str(target), "--out",
                                           str(folder / "repaired")])
    if fmt in ("metrics", "points"):
        copy = folder / "results"
        shutil.copytree(results, copy)
        target = copy / ("metrics.json" if fmt == "metrics" else "points.ply")
        target.write_bytes(mutation.data)
        # --save: the evaluation is written into the copy, as a transaction.
        return Run(fmt, mutation, target, ["evaluate", str(copy), "--tracks", str(results / "tracks.json"), "--save"])
    target = folder / ("eval_tracks.json" if fmt == "eval_tracks" else "camera_poses.json")
    target.write_bytes(mutation.data)
    if fmt == "eval_tracks":
        return Run(fmt, mutation, target, ["evaluate", str(results), "--tracks", str(target)])
    return Run(fmt, mutation, target, ["compare", str(target), str(results / "camera_poses.json")])


def cli_args(run: Run) -> Run:
    """The shared command lines, with what the Python CLI needs to be quick and quiet."""
    extra = {"calibrate": ["--no-report", "--no-progress"]}.get(run.args[0], [])
    return Run(run.fmt, run.mutation, run.file, [*run.args, *extra])


# ---------------------------------------------------------------------------------------
# Checks.


def problem_of(run: Run, answer: dict[str, Any]) -> str | None:
    """None when the run behaved, else what went wrong."""
    if "problem" in answer:
        return answer["problem"]
    status, stderr = answer["status"], answer["stderr"]
    if "Traceback" in stderr or "internal error" in stderr:
        return f"exit status {status} with a traceback: {stderr[-600:]!r}"
    # check's own statuses: a camera not confirmed (3), no trusted majority (4).
    if status not in (0, 1, 2) + ((3, 4) if run.args[0] == "check" else ()):
        return f"exit status {status}: {stderr[-300:]!r}"
    errors = [line for line in stderr.splitlines() if ": error: " in line]
    if status == 2:
        if run.fmt in PER_CAMERA:
            return f"a camera's intrinsics file stopped the whole run: {stderr[-300:]!r}"
        if len(errors) != 1:
            return f"exit status 2 with {len(errors)} error lines: {stderr[-300:]!r}"
        if str(run.file) not in errors[0]:
            return f"error line does not name {run.file.name}: {errors[0][:300]!r}"
        if len(errors[0]) > MAX_ERROR_LINE:
            return f"error line of {len(errors[0])} characters: {errors[0][:200]!r}..."
    if run.mutation.must_fail:
        if run.fmt in PER_CAMERA and (status != 1 or str(run.file) not in stderr):
            return f"exit status {status} without naming {run.file.name}: {stderr[-300:]!r}"
        if run.fmt not in PER_CAMERA and status != 2:
            return f"accepted (exit status {status}): {stderr[-300:]!r}"
    if "--save" in run.args and status != 0 and (run.file.parent / "evaluation.json").exists():
        return f"exit status {status} but evaluation.json was saved: {stderr[-300:]!r}"
    if run.args[0] == "check" and status in (1, 2, 4) and (run.file.parent / "repaired").exists():
        return f"exit status {status} but a repaired folder was written: {stderr[-300:]!r}"
    return None


# ---------------------------------------------------------------------------------------
# Tests.


def make_results(root: Path, inputs: Inputs) -> Path:
    """A results folder of the valid tracks (calibrated by a worker, as a user would)."""
    run = cli_args(prepare(root, inputs, "tracks", 0, Mutation("none", dumps(inputs.tracks), False)))
    worker = Worker()
    try:
        answer = worker.call(run.args)
    finally:
        worker.stop()
    assert answer.get("status") == 0, answer
    return Path(run.args[run.args.index("--out") + 1])


def test_mutated_input_files_fail_cleanly(tmp_path: Path) -> None:
    started = time.perf_counter()
    inputs = make_inputs(tmp_path / "inputs", SEED)
    results = make_results(tmp_path / "valid", inputs)
    rng = np.random.default_rng(SEED)
    mutations = all_mutations(inputs, rng, BUDGET)
    extra = results_mutations(results, rng)
    runs = [cli_args(prepare(tmp_path / "runs", inputs, fmt, index, mutation))
            for fmt, items in mutations.items() for index, mutation in enumerate(items)]
    runs += [prepare_results_run(tmp_path / "runs", results, fmt, index, mutation)
             for fmt, items in extra.items() for index, mutation in enumerate(items)]
    assert len(runs) >= MIN_FILES
    answers = run_all(runs)
    elapsed = time.perf_counter() - started
    failures = [f"{run.fmt} {run.mutation.label} ({run.file}): {problem}"
                for run, answer in zip(runs, answers) if (problem := problem_of(run, answer)) is not None]
    statuses = collections.Counter(answer.get("status", "hang/crash") for answer in answers)
    per_format = collections.Counter(run.fmt for run in runs)
    print(f"\nran calibproj (Python CLI) on {len(runs)} mutated files ("
          + ", ".join(f"{fmt} {count}" for fmt, count in per_format.items()) + "); exit statuses "
          + ", ".join(f"{status}: {count}" for status, count in sorted(statuses.items(), key=str))
          + f"; {elapsed:.1f} s")
    assert not failures, f"{len(failures)} of {len(runs)} runs misbehaved:\n" + "\n".join(failures)


def test_the_valid_inputs_are_accepted(tmp_path: Path) -> None:
    """The mutations start from inputs the commands take, so that a refusal is the
    mutation's doing."""
    inputs = make_inputs(tmp_path / "inputs", SEED)
    results = make_results(tmp_path / "valid", inputs)  # calibrate: status 0
    sequence = cli_args(prepare(tmp_path / "runs", inputs, "sequence", 0,
                                Mutation("none", dumps(inputs.sequence), False)))
    valid = [sequence, *(prepare_results_run(tmp_path / "runs", results, fmt, 0, Mutation("none", data, False))
                         for fmt, data in [("eval_tracks", (results / "tracks.json").read_bytes()),
                                           ("evaluate_intrinsics", (results / "intrinsics/cam1.json").read_bytes()),
                                           ("camera_poses", (results / "camera_poses.json").read_bytes()),
                                           ("metrics", (results / "metrics.json").read_bytes())])]
    answers = run_all(valid)
    # detect: every camera fails to synchronise (the videos hold no light code), status 1.
    assert [answer.get("status") for answer in answers] == [1, 0, 0, 0, 0], answers
    assert all(": error: " not in answer["stderr"] for answer in answers), answers


def test_a_hang_and_a_crash_are_caught(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The harness itself: a command that never answers is a hang, a dying worker a crash."""
    monkeypatch.setattr(sys.modules[__name__], "RUN_TIMEOUT_S", 2.0)
    worker = Worker()
    try:
        # A worker that reads its request and sleeps stands for a hang (the real one
        # is started by call(); replace its process before the request).
        worker.process = subprocess.Popen([sys.executable, "-c", "import sys, time; sys.stdin.readline(); "
                                           "time.sleep(60)"], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        assert worker.call(["compare", "a", "b"])["problem"].startswith("hang")
        assert worker.process is None
        worker.process = subprocess.Popen([sys.executable, "-c", "import os, sys; sys.stdin.readline(); "
                                           "os.abort()"], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        assert "died" in worker.call(["compare", "a", "b"])["problem"]
    finally:
        worker.stop()


if __name__ == "__main__" and sys.argv[1:] == ["--serve"]:
    serve()
