"""calibproj-native writes its outputs as the Python commands do, through the core's one
transaction (cpp/calibproj/formats/output_folder.h): a results folder replaced whole or not
at all, the same lock (a Python run and a native run on one output exclude each other), the
same refusals in one line, the same exit statuses."""

from __future__ import annotations

import contextlib
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from calibproj.formats.output_folder import OutputBusyError, OutputFile, OutputFolder
from calibproj.simulate import simulate_tracks
from test_native import NATIVE, error_line, run_native, run_python
from test_output_folder import siblings, snapshot, without_privileges

EXIT_FAILURE, EXIT_USAGE, EXIT_INTERRUPTED = 1, 2, 130
WAIT_S = 60.0


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    """Tracks of the small room (3 cameras) with their intrinsics."""
    out = tmp_path_factory.mktemp("small")
    simulate_tracks("small", out, noise_px=0.3, seed=2)
    return out


def calibrate_args(sim: Path, out: Path, *extra: str) -> list[str]:
    return ["calibrate", "--tracks", str(sim / "tracks.json"), "--intrinsics", str(sim / "intrinsics"),
            "--out", str(out), *extra]


def detect_args(tmp_path: Path, out: Path) -> list[str]:
    """A detect run whose inputs do not exist: the output is checked before them."""
    return ["detect", str(tmp_path / "no-videos"), "--sequence", str(tmp_path / "no-sequence.json"),
            "--intrinsics", str(tmp_path / "no-intrinsics"), "--out", str(out), "--no-progress"]


def test_force_replaces_the_whole_folder(small: Path, tmp_path: Path) -> None:
    out = tmp_path / "results"
    assert run_native(*calibrate_args(small, out)).returncode == 0
    # What an earlier run of the Python command left beside the native command's files.
    (out / "colmap").mkdir()
    (out / "colmap" / "cameras.txt").write_text("stale export")
    (out / "report.html").write_text("stale report")
    before = snapshot(out)

    refused = run_native(*calibrate_args(small, out))
    assert refused.returncode == EXIT_USAGE
    assert error_line(refused) == (f"{out}: already holds results (camera_poses.json, metrics.json, points.ply); "
                                   f"use --force to overwrite them")
    assert snapshot(out) == before

    forced = run_native(*calibrate_args(small, out, "--force"))
    assert forced.returncode == 0, forced.stderr
    assert sorted(p.name for p in out.iterdir()) == ["camera_poses.json", "intrinsics", "metrics.json", "points.ply",
                                                     "provenance.json", "tracks.json", "uncertainty.json"]
    assert snapshot(out)["camera_poses.json"] == before["camera_poses.json"]  # the same calibration again
    assert siblings(out) == []


def test_force_never_deletes_a_folder_of_other_files(small: Path, tmp_path: Path) -> None:
    out = tmp_path / "notes"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    for force in ([], ["--force"]):
        result = run_native(*calibrate_args(small, out, *force))
        assert result.returncode == EXIT_USAGE
        assert error_line(result) == f"{out}: is not empty (notes.txt) and holds no output of this command; " \
                                     "choose another folder"
    assert snapshot(out) == {"notes.txt": b"mine"} and siblings(out) == []


def test_a_link_as_out_writes_where_it_leads(small: Path, tmp_path: Path) -> None:
    link = tmp_path / "latest"
    link.symlink_to("run1")  # nothing there yet
    assert run_native(*calibrate_args(small, link)).returncode == 0
    assert link.is_symlink() and (tmp_path / "run1" / "camera_poses.json").is_file()
    refused = run_native(*calibrate_args(small, link))
    assert error_line(refused).startswith(f"{tmp_path / 'run1'}: already holds results")
    assert run_native(*calibrate_args(small, link, "--force")).returncode == 0
    assert link.is_symlink() and siblings(tmp_path / "run1") == []


def test_unwritable_outputs_give_the_python_line(small: Path, tmp_path: Path) -> None:
    a_file = tmp_path / "results.txt"
    a_file.write_text("x")
    cases = {
        "a file as --out": calibrate_args(small, a_file),
        "a folder inside a file": calibrate_args(small, a_file / "results"),
        "a folder as detect's --out": detect_args(tmp_path, tmp_path),
        "a file inside a file as detect's --out": detect_args(tmp_path, a_file / "tracks.json"),
    }
    for case, args in cases.items():
        python, native = run_python(*args), run_native(*args)
        assert python.returncode == native.returncode == EXIT_USAGE, (case, python.stderr, native.stderr)
        assert error_line(native) == error_line(python), case
        assert str(a_file if "file" in case else tmp_path) in error_line(native), case
    assert a_file.read_text() == "x"


def test_detect_replaces_an_existing_file_only_when_forced_and_never_its_sequence(tmp_path: Path) -> None:
    """Found by probing: `detect --out` (both tools) overwrote any existing file, the
    run's own --sequence included. Both now refuse in the same line, before the inputs
    are read, and leave the file as it was."""
    existing = tmp_path / "tracks.json"
    existing.write_text("earlier")
    sequence = tmp_path / "sequence.json"
    sequence.write_text("the projection")
    as_sequence = detect_args(tmp_path, sequence)
    as_sequence[as_sequence.index("--sequence") + 1] = str(sequence)
    cases = {
        "an existing file": (detect_args(tmp_path, existing), "exists (use --force to replace it)"),
        "the run's sequence, forced": ([*as_sequence, "--force"], "is an input of this run"),
    }
    for case, (args, message) in cases.items():
        python, native = run_python(*args), run_native(*args)
        assert python.returncode == native.returncode == EXIT_USAGE, (case, python.stderr, native.stderr)
        assert error_line(native) == error_line(python), case
        assert message in error_line(native), case
    assert existing.read_text() == "earlier" and sequence.read_text() == "the projection"
    # Forced, an existing file is replaced as before: here the missing inputs are next.
    forced = run_native(*detect_args(tmp_path, existing), "--force")
    assert forced.returncode == EXIT_USAGE and "no-sequence.json" in error_line(forced)


def test_a_read_only_parent_is_named(small: Path, tmp_path: Path) -> None:
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        result = subprocess.run(without_privileges([str(NATIVE), *calibrate_args(small, locked / "results")]),
                                capture_output=True, text=True)
    finally:
        locked.chmod(0o755)
    assert result.returncode == EXIT_USAGE
    assert error_line(result) == f"{locked / 'results'}: cannot write in {locked} (permission denied)"


def test_a_python_run_holding_the_output_keeps_native_runs_out(small: Path, tmp_path: Path) -> None:
    out = tmp_path / "busy"
    holder = OutputFolder(out).open()
    try:
        started = time.perf_counter()
        result = run_native(*calibrate_args(small, out, "--force"))
        assert result.returncode == EXIT_FAILURE
        assert error_line(result) == (f"{out}: another calibproj run is writing it (lock held on "
                                      f"{tmp_path / '.busy.lock'}); wait for it to end or choose another output")
        assert time.perf_counter() - started < WAIT_S / 4  # at once, not after the calibration
        assert holder.staging.is_dir() and not out.exists()
    finally:
        holder.abort()

    tracks = tmp_path / "tracks.json"
    file_holder = OutputFile(tracks).open()
    try:
        result = run_native(*detect_args(tmp_path, tracks))
        assert result.returncode == EXIT_FAILURE
        assert "another calibproj run is writing it" in error_line(result)
    finally:
        file_holder.close()
    assert siblings(out) == [] and siblings(tracks) == []


def full_pipe() -> tuple[int, int]:
    """A pipe whose buffer is full: a process writing to it blocks until it is read."""
    read_end, write_end = os.pipe()
    os.set_blocking(write_end, False)
    for chunk in (b"\0" * 4096, b"\0"):
        try:
            while True:
                os.write(write_end, chunk)
        except BlockingIOError:
            pass
    os.set_blocking(write_end, True)  # the child shares the open file, and must block
    return read_end, write_end


def wait_for(condition, what: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while not condition():
        assert time.monotonic() < deadline, f"no {what} after {WAIT_S:.0f} s"
        time.sleep(0.01)


@pytest.mark.parametrize("signal_number", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_an_interrupted_run_leaves_the_previous_folder(small: Path, tmp_path: Path, signal_number: int) -> None:
    out = tmp_path / "results"
    assert run_native(*calibrate_args(small, out)).returncode == 0
    (out / "colmap").mkdir()
    (out / "colmap" / "cameras.txt").write_text("an earlier export")
    before = snapshot(out)

    # stderr is a full pipe: the run stops at its first progress line, in the middle of
    # the registration (its staging folder made, its results not written), until the
    # pipe is read. The signal comes while it waits there.
    read_end, write_end = full_pipe()
    process = subprocess.Popen([str(NATIVE), *calibrate_args(small, out, "--force")], stdout=subprocess.DEVNULL,
                               stderr=write_end)
    os.close(write_end)
    stderr = bytearray()
    reader = threading.Thread(target=lambda: stderr.extend(drain(read_end)))
    try:
        wait_for(lambda: any(name.startswith(".results.tmp-") for name in siblings(out)), "staging folder")
        with pytest.raises(OutputBusyError):  # the native run holds the lock Python takes
            OutputFolder(out, force=True).open()
        process.send_signal(signal_number)
        reader.start()
        assert process.wait(timeout=WAIT_S) == EXIT_INTERRUPTED
        reader.join(timeout=WAIT_S)
    finally:
        process.kill()
        process.wait()
    lines = stderr.replace(b"\0", b"").decode().splitlines()
    assert lines[-1] == "calibproj-native calibrate: interrupted", lines
    assert snapshot(out) == before and siblings(out) == []


def drain(fd: int) -> bytes:
    with os.fdopen(fd, "rb") as pipe:
        return pipe.read()


def test_a_camera_not_calibrated_gives_status_1_and_the_others(small: Path, tmp_path: Path) -> None:
    intrinsics = tmp_path / "intrinsics"
    intrinsics.mkdir()
    for camera in ("cam1", "cam2"):
        shutil.copy(small / "intrinsics" / f"{camera}.json", intrinsics)
    out = tmp_path / "results"
    result = run_native("calibrate", "--tracks", str(small / "tracks.json"), "--intrinsics", str(intrinsics),
                        "--out", str(out))
    assert result.returncode == EXIT_FAILURE, result.stderr
    poses = json.loads((out / "camera_poses.json").read_text())
    assert sorted(poses["cameras"]) == ["cam1", "cam2"] and list(poses["failed"]) == ["cam3"]


def test_a_bad_intrinsics_file_fails_its_camera_only(small: Path, tmp_path: Path) -> None:
    """As in the Python command: true in K fails cam2 alone, with the file and the
    problem; the others are calibrated and the run exits 1. A second file for one
    camera fails that camera too."""
    intrinsics = tmp_path / "intrinsics"
    shutil.copytree(small / "intrinsics", intrinsics)
    bad = json.loads((intrinsics / "cam2.json").read_text())
    bad["K"][0][0] = True
    (intrinsics / "cam2.json").write_text(json.dumps(bad))
    out = tmp_path / "results"
    args = ["calibrate", "--tracks", str(small / "tracks.json"), "--intrinsics", str(intrinsics), "--out", str(out)]
    result = run_native(*args)
    assert result.returncode == EXIT_FAILURE and ": error: " not in result.stderr, result.stderr
    poses = json.loads((out / "camera_poses.json").read_text())
    assert sorted(poses["cameras"]) == ["cam1", "cam3"] and list(poses["failed"]) == ["cam2"]
    assert str(intrinsics / "cam2.json") in poses["failed"]["cam2"]
    assert f"camera cam2: {poses['failed']['cam2']}, left out" in result.stderr
    shutil.copy(intrinsics / "cam3.json", intrinsics / "cam3.yaml")
    result = run_native(*args, "--force")
    failed = json.loads((out / "camera_poses.json").read_text())["failed"]
    assert "a second intrinsics file for camera 'cam3'" in failed["cam3"], result.stderr


def test_bad_invocations_exit_with_status_2() -> None:
    assert run_native("calibrate", "--no-such-option").returncode == EXIT_USAGE
    assert run_native().returncode == EXIT_USAGE
    assert run_native("calibrate", "--help").returncode == 0


@contextlib.contextmanager
def immutable(path: Path) -> Iterator[None]:
    """``path`` with the immutable flag (chattr +i) for the block; the test is skipped
    where the flag cannot be set (no CAP_LINUX_IMMUTABLE, a file system without it)."""
    if shutil.which("chattr") is None:
        pytest.skip("no chattr")
    if subprocess.run(["chattr", "+i", str(path)], capture_output=True).returncode != 0:
        pytest.skip("chattr +i is not permitted here")
    try:
        yield
    finally:
        subprocess.run(["chattr", "-i", str(path)], check=True)


def test_an_output_that_cannot_be_replaced_is_found_before_the_work(small: Path, tmp_path: Path) -> None:
    """Found by probing: an immutable results folder was found after the ingest,
    registration and report, in both tools. The inputs here do not exist, so a message
    about them would mean the work had started."""
    out = tmp_path / "results"
    assert run_native(*calibrate_args(small, out)).returncode == 0
    tracks = tmp_path / "tracks.json"
    tracks.write_text("{}")
    missing_tracks = ["calibrate", "--tracks", str(tmp_path / "none.json"), "--intrinsics", str(small / "intrinsics"),
                      "--out", str(out), "--force"]
    with immutable(out), immutable(tracks):
        for args in (missing_tracks, [*detect_args(tmp_path, tracks), "--force"]):
            python, native = run_python(*args), run_native(*args)
            assert python.returncode == native.returncode == EXIT_USAGE, (python.stderr, native.stderr)
            assert error_line(native) == error_line(python)
            assert error_line(native).endswith("cannot be replaced (it is immutable or append-only; "
                                               "chattr -i -a lifts that)"), error_line(native)
        assert siblings(out) == [] and siblings(tracks) == []


def test_a_file_size_limit_fails_the_run_cleanly(small: Path, tmp_path: Path) -> None:
    """Found by probing: under `ulimit -f` calibproj-native died of SIGXFSZ, leaving its
    lock and staging folder."""
    def limited() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))

    for tool in (NATIVE, None):
        out = tmp_path / ("native" if tool else "python")
        command = [str(tool)] if tool else [sys.executable, "-m", "calibproj"]
        result = subprocess.run([*command, *calibrate_args(small, out)], capture_output=True, text=True,
                                preexec_fn=limited, timeout=300)
        assert result.returncode == EXIT_USAGE, result.stderr
        assert "File too large" in error_line(result), result.stderr
        assert not out.exists() and siblings(out) == []


def test_a_failed_run_leaves_no_folder_it_made_for_its_output(small: Path, tmp_path: Path) -> None:
    """Found by probing: a failed `detect` left its empty output folder behind."""
    (tmp_path / "kept").mkdir()
    for tool in (run_python, run_native):
        for out in (tmp_path / "new" / "deeper" / "tracks.json", tmp_path / "kept" / "new" / "tracks.json"):
            result = tool(*detect_args(tmp_path, out))
            assert result.returncode == EXIT_USAGE and "no-" in error_line(result), result.stderr
        result = tool("calibrate", "--tracks", str(tmp_path / "none.json"), "--intrinsics", str(small / "intrinsics"),
                      "--out", str(tmp_path / "made" / "results"))
        assert result.returncode == EXIT_USAGE and "none.json" in error_line(result), result.stderr
        assert sorted(p.name for p in tmp_path.iterdir()) == ["kept"] and not any((tmp_path / "kept").iterdir())
