"""Fuzzing of calibproj-native's input files: tracks.json and intrinsics files for
`calibrate`, sequence.json and intrinsics files for `detect`, mutated from a fixed
seed (deep nesting, wrong types, booleans for numbers, NaN and infinity literals, huge
and tiny numbers, duplicate camera names, truncation, byte flips, empty files, a
projector at 1e-300 fps, ...).

Every run must end by itself (no signal, no hang) with exit status 0, 1 or 2; status 2
(a bad input) with exactly one error line on stderr naming the mutated file. The
mutations that break the format must give status 2, except in a camera's own
intrinsics file: that camera fails (status 1, the file named), the others go on.

Run alone (with -s for the summary line):
    PYTHONPATH=python python -m pytest tests/test_fuzz_native.py -q -s
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import json
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

# The tests folder is on sys.path under pytest.
from fuzz_inputs import Mutation, Run, all_mutations, dumps, fill, make_inputs, prepare
from test_native import find_native

SEED = 20250612
RUN_TIMEOUT_S = 30.0
WORKERS = 2
# Mutated files per input format.
BUDGET = {"tracks": 170, "calibrate_intrinsics": 110, "sequence": 170, "detect_intrinsics": 60}
MIN_FILES = 500
# A camera's own file: a bad one fails that camera (status 1), naming the file; the others go on.
PER_CAMERA_FORMATS = {"calibrate_intrinsics", "detect_intrinsics"}


# ---------------------------------------------------------------------------------------
# Runs.


def python_refuses(run: Run) -> str | None:
    """The Python package's message for a mutated file its reader refuses (None: read)."""
    from calibproj.formats.intrinsics import read_intrinsics
    from calibproj.formats.jsonio import FormatError
    from calibproj.sequence.sequence import Sequence
    from calibproj.formats.tracks import Tracks

    readers = {"sequence": Sequence.load, "tracks": Tracks.read}
    try:
        readers.get(run.fmt, read_intrinsics)(run.file)
    except FormatError as error:
        return str(error)
    return None


def tools_disagree(run: Run, outcome: Outcome) -> str | None:
    """None when calibproj-native's verdict on a mutated file is the Python package's,
    else the difference. Native refuses a tracks or sequence file with status 2 naming
    it, and fails the camera of an intrinsics file naming it."""
    refused_by_python = python_refuses(run)
    refused_by_native = outcome.refused if run.fmt not in PER_CAMERA_FORMATS else outcome.names_file
    if (refused_by_python is not None) == refused_by_native:
        return None
    return f"Python {'refuses' if refused_by_python else 'reads'} it ({refused_by_python}), native does not"


@dataclasses.dataclass
class Outcome:
    problem: str | None  # None when the run behaved, else what went wrong
    refused: bool = False  # status 2 with one error line naming the mutated file
    names_file: bool = False  # the mutated file named anywhere on stderr


def execute(native: Path, run: Run) -> Outcome:
    try:
        result = subprocess.run([str(native), *run.args], capture_output=True, timeout=RUN_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        return Outcome(f"hang (no exit within {RUN_TIMEOUT_S:.0f} s)")
    stderr = result.stderr.decode(errors="replace")
    errors = [line for line in stderr.splitlines() if ": error: " in line]
    refused = result.returncode == 2 and len(errors) == 1 and str(run.file) in errors[0]
    return Outcome(misbehaviour(run, result.returncode, stderr, errors), refused, str(run.file) in stderr)


def misbehaviour(run: Run, returncode: int, stderr: str, errors: list[str]) -> str | None:
    """None when the run behaved, else what went wrong."""
    if returncode < 0:
        return f"killed by signal {-returncode}: {stderr[-300:]!r}"
    if returncode not in (0, 1, 2):
        return f"exit status {returncode}: {stderr[-300:]!r}"
    if returncode == 2:
        if len(errors) != 1:
            return f"exit status 2 with {len(errors)} error lines: {stderr[-300:]!r}"
        if run.fmt in PER_CAMERA_FORMATS:
            return f"a camera's file stopped the whole run: {errors[0][:300]!r}"
        if str(run.file) not in errors[0]:
            return f"error line does not name {run.file.name}: {errors[0][:300]!r}"
        if len(errors[0]) > 2000:
            return f"error line of {len(errors[0])} characters"
    if run.fmt in PER_CAMERA_FORMATS:
        if run.mutation.must_fail and (returncode != 1 or str(run.file) not in stderr):
            return f"exit status {returncode} without naming {run.file.name}: {stderr[-300:]!r}"
    elif run.mutation.must_fail and returncode != 2:
        return f"accepted (exit status {returncode}): {stderr[-300:]!r}"
    return None


@pytest.fixture(scope="module")
def native() -> Path:
    return find_native()


def test_mutated_input_files_fail_cleanly(native: Path, tmp_path: Path) -> None:
    inputs = make_inputs(tmp_path / "inputs", SEED)
    rng = np.random.default_rng(SEED)
    mutations = all_mutations(inputs, rng, BUDGET)
    runs = [prepare(tmp_path / "runs", inputs, fmt, index, mutation)
            for fmt, items in mutations.items() for index, mutation in enumerate(items)]
    assert len(runs) >= MIN_FILES
    started = time.perf_counter()
    with concurrent.futures.ThreadPoolExecutor(WORKERS) as pool:
        outcomes = list(pool.map(lambda run: execute(native, run), runs))
    elapsed = time.perf_counter() - started
    failures = [f"{run.fmt} {run.mutation.label} ({run.file}): {outcome.problem}"
                for run, outcome in zip(runs, outcomes) if outcome.problem is not None]
    # One reader per format: the Python package refuses exactly the files native refuses.
    failures += [f"{run.fmt} {run.mutation.label} ({run.file}): {disagreement}" for run, outcome in zip(runs, outcomes)
                 if (disagreement := tools_disagree(run, outcome)) is not None]
    sequences = [(run, outcome) for run, outcome in zip(runs, outcomes) if run.fmt == "sequence"]
    refused = sum(outcome.refused for _, outcome in sequences)
    assert 0 < refused < len(sequences), "the sequence mutants must include files both tools read and refuse"
    print(f"\nran calibproj-native on {len(runs)} mutated files ("
          + ", ".join(f"{fmt} {len(items)}" for fmt, items in mutations.items()) + f") in {elapsed:.1f} s; "
          f"of the sequence files both tools refuse {refused} and read {len(sequences) - refused}")
    assert not failures, f"{len(failures)} of {len(runs)} runs misbehaved:\n" + "\n".join(failures)


def test_the_valid_inputs_are_accepted(native: Path, tmp_path: Path) -> None:
    """The mutations start from inputs the executable takes, so that a refusal is the
    mutation's doing."""
    inputs = make_inputs(tmp_path / "inputs", SEED)
    for fmt, document in [("tracks", inputs.tracks), ("sequence", inputs.sequence)]:
        run = prepare(tmp_path / "runs", inputs, fmt, 0, Mutation("none", dumps(document), False))
        result = subprocess.run([str(native), *run.args], capture_output=True, text=True, timeout=RUN_TIMEOUT_S)
        # detect: every camera fails to synchronise (the videos hold no light code), status 1.
        assert result.returncode == (0 if fmt == "tracks" else 1), result.stderr
        assert ": error: " not in result.stderr


# ---------------------------------------------------------------------------------------
# The results folder `check` reads: camera_poses.json, metrics.json and points.ply.

RESULTS_BUDGET = {"camera_poses.json": 70, "metrics.json": 70}
CHECK_STATUSES = (0, 1, 2, 3, 4)  # 3 and 4: not confirmed, untrusted (README, "Exit status")


def ply_mutations(text: str, rng: np.random.Generator) -> list[Mutation]:
    """Line-level damage to points.ply: header, counts, vertices, ids."""
    lines = text.splitlines()
    end = lines.index("end_header")
    first = lines[end + 1].split()

    def with_row(words: list[str]) -> bytes:
        return "\n".join([*lines[:end + 1], " ".join(words), *lines[end + 2:]]).encode() + b"\n"

    out = [Mutation("empty file", b"", True),
           Mutation("binary garbage", rng.integers(0, 256, 500, np.uint8).tobytes(), True),
           Mutation("no schema comment", text.replace("comment schema calibproj.points/1\n", "").encode(), True),
           Mutation("no end_header", text.replace("end_header\n", "").encode(), True),
           Mutation("one vertex missing", "\n".join(lines[:-1]).encode(), True),
           Mutation("one vertex too many", (text + lines[-1] + "\n").encode(), True),
           Mutation("vertex count not a number", text.replace("element vertex", "element vertex x", 1).encode(), True),
           Mutation("negative vertex count", text.replace(f"element vertex {len(lines) - end - 1}",
                                                          "element vertex -3").encode(), True),
           Mutation("not UTF-8", text.replace("property double x", "property double \xff").encode("latin-1"), True),
           Mutation("CRLF line ends", text.replace("\n", "\r\n").encode(), False),
           Mutation("a duplicate id", with_row([*first[:3], lines[end + 2].split()[3]]), True),
           Mutation("a fractional id", with_row([*first[:3], "1.5"]), True),
           Mutation("a negative id", with_row([*first[:3], "-4"]), True),
           Mutation("an id of 2**53", with_row([*first[:3], str(2 ** 53)]), True),
           Mutation("a column missing", with_row(first[:3]), True),
           Mutation("a column too many", with_row([*first, "7"]), True)]
    for word in ("nan", "inf", "-inf", "1e400", "abc", "0x10", "--1", "1e", ".", "+2.5", "1E-3"):
        position = int(rng.integers(3))
        words = list(first)
        words[position] = word
        out.append(Mutation(f"coordinate {position} = {word}", with_row(words),
                            word not in ("+2.5", "1E-3")))
    return out


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory) -> tuple[Path, Path]:
    """A results folder of the small room (geometric simulation) and a check's tracks."""
    from calibproj.pipeline import calibrate
    from calibproj.simulate import simulate_tracks

    folder = tmp_path_factory.mktemp("calibrated")
    first = simulate_tracks("small", folder / "first", noise_px=0.1, seed=3)
    calibrate(first.tracks, first.intrinsics, out=folder / "results", report=False)
    again = simulate_tracks("small", folder / "again", noise_px=0.1, seed=4)
    return folder / "results", folder / "again" / "tracks.json"


def test_mutated_results_folders_fail_cleanly(native: Path, calibrated: tuple[Path, Path], tmp_path: Path) -> None:
    """`calibproj-native check` on a results folder with one damaged file: an exit status
    of the command, never a crash or a hang; a refusal is one line naming the file, and
    it refuses exactly the folders the Python package refuses to load (both read them
    through the core's one reader: this holds the Python side to it)."""
    import shutil

    from calibproj.formats.calibration import Calibration
    from calibproj.formats.jsonio import FormatError

    results, tracks = calibrated
    rng = np.random.default_rng(SEED)
    mutations = {name: fill([], json.loads((results / name).read_text()), rng, budget)
                 for name, budget in RESULTS_BUDGET.items()}
    mutations["points.ply"] = ply_mutations((results / "points.ply").read_text(), rng)
    failures, refused = [], 0
    for name, items in mutations.items():
        for index, mutation in enumerate(items):
            folder = tmp_path / f"{name}-{index:03d}"
            shutil.copytree(results, folder)
            (folder / name).write_bytes(mutation.data)
            damaged = folder / name
            try:
                result = subprocess.run([str(native), "check", str(folder), "--tracks", str(tracks)],
                                        capture_output=True, timeout=RUN_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                failures.append(f"{name} {mutation.label}: hang")
                continue
            label = f"{name} {mutation.label}"
            errors = [line for line in result.stderr.decode(errors="replace").splitlines() if ": error: " in line]
            native_refuses = result.returncode == 2 and len(errors) == 1 and str(damaged) in errors[0]
            if result.returncode not in CHECK_STATUSES:
                failures.append(f"{label}: exit status {result.returncode}: {result.stderr[-300:]!r}")
            elif result.returncode == 2 and not native_refuses:
                failures.append(f"{label}: status 2 without one error line naming the file: {errors}")
            try:
                Calibration.load(folder)
                python_refuses = None
            except FormatError as error:
                python_refuses = str(error)
            if (python_refuses is not None) != native_refuses:
                failures.append(f"{label}: Python {'refuses' if python_refuses else 'reads'} it "
                                f"({python_refuses}), native {'does not' if python_refuses else 'refuses'}")
            if mutation.must_fail and not native_refuses:
                failures.append(f"{label}: accepted (exit status {result.returncode})")
            refused += native_refuses
    total = sum(map(len, mutations.values()))
    print(f"\nran calibproj-native check on {total} damaged results folders; both tools refuse {refused}")
    assert 0 < refused < total
    assert not failures, f"{len(failures)} of {total} runs misbehaved:\n" + "\n".join(failures)
