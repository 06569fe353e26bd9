"""Output folders as transactions: replaced whole, locked, never half-written, and
refused early (before any long work) in one line when they cannot be written."""

from __future__ import annotations

import errno
import json
import logging
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from calibproj import pipeline
from calibproj.cli.main import main
from calibproj.formats import jsonio
from calibproj.formats.output_folder import OutputBusyError, OutputError, OutputFile, OutputFolder
from calibproj.simulate import simulate_tracks
from calibproj.formats.tracks import Tracks


def siblings(path: Path) -> list[str]:
    """Everything beside ``path`` that belongs to it (staging, aside, lock)."""
    return sorted(p.name for p in path.parent.iterdir() if p.name.startswith(f".{path.name}."))


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def one_error_line(capsys: pytest.CaptureFixture) -> str:
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1, error
    assert "Traceback" not in error
    return error


# -- the folder transaction ------------------------------------------------------------------


def test_force_replaces_the_whole_previous_folder(tmp_path: Path) -> None:
    out = tmp_path / "out"
    (out / "colmap").mkdir(parents=True)
    (out / "result.json").write_text("old")
    (out / "colmap" / "cameras.txt").write_text("nine cameras")
    with OutputFolder(out, force=True, signature=["result.json"]) as folder:
        staging = folder.staging
        assert staging.parent == tmp_path and staging.name.startswith(".out.tmp-")
        (staging / "result.json").write_text("new")
        assert (out / "colmap" / "cameras.txt").exists()  # untouched until the commit
    assert snapshot(out) == {"result.json": b"new"}
    assert not staging.exists() and siblings(out) == []
    assert oct(out.stat().st_mode & 0o777) == oct(0o777 & ~_umask())


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_an_existing_folder_needs_force_and_force_spares_other_folders(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    for force in (False, True):
        with pytest.raises(OutputError, match=r"out: is not empty \(notes.txt\) and holds no output of this command"):
            OutputFolder(out, force=force, signature=["result.json"]).open()
    assert snapshot(out) == {"notes.txt": b"mine"} and siblings(out) == []
    (out / "result.json").write_text("old")
    with pytest.raises(OutputError, match=r"out: already holds results \(result.json\); use --force to overwrite"):
        OutputFolder(out, signature=["result.json"]).open()
    with pytest.raises(OutputError, match=r"out: already exists; use --force to replace it"):
        OutputFolder(out).open()
    # An empty folder (made beforehand) is simply filled.
    empty = tmp_path / "empty"
    empty.mkdir()
    with OutputFolder(empty) as folder:
        (folder.staging / "a").write_text("a")
    assert snapshot(empty) == {"a": b"a"}


def test_an_interrupted_run_leaves_the_previous_folder_intact(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "result.json").write_text("old")
    with pytest.raises(KeyboardInterrupt):
        with OutputFolder(out, force=True) as folder:
            (folder.staging / "result.json").write_text("half")
            raise KeyboardInterrupt
    assert snapshot(out) == {"result.json": b"old"} and siblings(out) == []
    # A new folder is never created by a failed run.
    with pytest.raises(RuntimeError):
        with OutputFolder(tmp_path / "new") as folder:
            (folder.staging / "result.json").write_text("half")
            raise RuntimeError("failed")
    assert not (tmp_path / "new").exists() and siblings(tmp_path / "new") == []


def test_what_a_killed_run_left_is_tidied_by_the_next(tmp_path: Path) -> None:
    out = tmp_path / "out"
    staging = tmp_path / ".out.tmp-dead"
    staging.mkdir()
    (staging / "result.json").write_text("half")
    # Killed between the two renames of a commit: the previous folder is aside.
    aside = tmp_path / ".out.old-dead" / "previous"
    aside.mkdir(parents=True)
    (aside / "result.json").write_text("old")
    folder = OutputFolder(out, force=True).open()
    assert snapshot(out) == {"result.json": b"old"}
    assert siblings(out) == sorted([".out.lock", folder.staging.name])
    folder.abort()
    assert siblings(out) == []


def test_a_second_writer_of_the_same_folder_fails_at_once(tmp_path: Path) -> None:
    out = tmp_path / "out"
    first = OutputFolder(out).open()
    started = time.perf_counter()
    with pytest.raises(OutputBusyError, match="another calibproj run is writing it"):
        OutputFolder(out).open()
    with pytest.raises(OutputBusyError):
        OutputFolder(out, force=True).open()
    assert time.perf_counter() - started < 1.0
    first.commit()
    with OutputFolder(out, force=True):  # free again once the first has finished
        pass


def test_paths_that_cannot_be_written_are_named(tmp_path: Path) -> None:
    a_file = tmp_path / "file"
    a_file.write_text("x")
    with pytest.raises(OutputError, match=f"{a_file}: exists and is not a folder"):
        OutputFolder(a_file).open()
    with pytest.raises(OutputError, match=f"{a_file / 'out'}: {a_file} is not a folder"):
        OutputFolder(a_file / "out").open()
    with pytest.raises(OutputError, match=f"{tmp_path}: is a folder"):
        OutputFile(tmp_path).open()


# The capabilities that let root write anywhere: dropped, root is bound by permissions.
DROPPED_CAPABILITIES = "--bounding-set=-dac_override,-dac_read_search"


def without_privileges(command: list[str]) -> list[str]:
    """``command`` run as permissions bind it: for root, without the capabilities that
    let it write anywhere (setpriv drops them from the child's bounding set)."""
    if os.geteuid() != 0:
        return command
    if shutil.which("setpriv") is None or subprocess.run(["setpriv", DROPPED_CAPABILITIES, "true"],
                                                         capture_output=True).returncode != 0:
        pytest.skip("root writes into read-only folders, and this machine cannot drop that right")
    return ["setpriv", DROPPED_CAPABILITIES, *command]


def test_a_folder_without_write_permission_is_named(tmp_path: Path) -> None:
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    code = ("from calibproj.formats.output_folder import OutputError, OutputFile, OutputFolder\n"
            "for output in (OutputFolder(%r), OutputFile(%r)):\n"
            "    try:\n"
            "        output.open()\n"
            "    except OutputError as error:\n"
            "        print(error)\n" % (str(locked / "out"), str(locked / "tracks.json")))
    try:
        result = subprocess.run(without_privileges([sys.executable, "-c", code]), capture_output=True, text=True,
                                timeout=120)
    finally:
        locked.chmod(0o755)
    assert result.stdout.splitlines() == [f"{locked / 'out'}: cannot write in {locked} (permission denied)",
                                          f"{locked / 'tracks.json'}: cannot write in {locked} (permission denied)"], \
        result.stderr


def test_a_full_disk_is_found_before_the_work(tmp_path: Path) -> None:
    """A disk with less free space than the output needs to start (here: more than any
    disk has) is refused, and the folders made for the output are removed again."""
    needed = 2**60
    with pytest.raises(OutputError, match=f"{tmp_path / 'a' / 'out'}: the disk is full"):
        OutputFolder(tmp_path / "a" / "out", min_free_bytes=needed).open()
    with pytest.raises(OutputError, match=f"{tmp_path / 'a' / 'tracks.json'}: the disk is full"):
        OutputFile(tmp_path / "a" / "tracks.json", min_free_bytes=needed).open()
    assert not (tmp_path / "a").exists()


def test_a_write_that_fails_is_named_and_leaves_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "result.json").write_text("old")

    def full(path, data):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(jsonio, "atomic_write_bytes", full)
    with pytest.raises(OutputError, match=f"{out}: cannot write the output \\(No space left on device\\)"):
        with OutputFolder(out, force=True) as folder, folder.writing() as staging:
            jsonio.atomic_write_text(staging / "result.json", "new")
    assert snapshot(out) == {"result.json": b"old"} and siblings(out) == []


# -- the commands ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    """Tracks of the small room (3 cameras) with their intrinsics."""
    out = tmp_path_factory.mktemp("small")
    simulate_tracks("small", out, noise_px=0.3, seed=2)
    return out


def calibrate_args(sim: Path, out: Path, *extra: str, tracks: Path | None = None) -> list[str]:
    # Simulated tracks have independent errors (nothing shared to discount or shift): no
    # camera is weak, and a failure's error line is all a run prints.
    return ["calibrate", "--tracks", str(tracks or sim / "tracks.json"), "--intrinsics", str(sim / "intrinsics"),
            "--out", str(out), "--no-progress", "--error-correlation", "0", "--shared-error-shift", "0",
            "--shared-error-field", "0", *extra]


def test_calibrate_force_leaves_nothing_of_the_previous_run(small: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "results"
    assert main(calibrate_args(small, out, "--export", "colmap")) == 0
    assert (out / "colmap" / "cameras.txt").read_text().count(" PINHOLE ") + \
        (out / "colmap" / "cameras.txt").read_text().count(" OPENCV ") == 3
    assert (out / "report" / "camera_cam3_errors.png").is_file()
    # Without --force the previous results stay, and nothing was computed.
    assert main(calibrate_args(small, out)) == 2
    assert "use --force" in one_error_line(capsys) and (out / "colmap").is_dir()
    # Two cameras, no export: nothing of the three-camera run remains.
    two = tmp_path / "two.json"
    Tracks.read(small / "tracks.json").keep_cameras(["cam1", "cam2"]).write(two)
    assert main(calibrate_args(small, out, "--force", tracks=two)) == 0
    assert not (out / "colmap").exists() and not (out / "report" / "camera_cam3_errors.png").exists()
    assert sorted(p.name for p in (out / "intrinsics").iterdir()) == ["cam1.json", "cam2.json"]
    assert sorted(json.loads((out / "camera_poses.json").read_text())["cameras"]) == ["cam1", "cam2"]
    assert siblings(out) == []


@pytest.fixture
def no_ingest(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> list[str]:
    """A videos folder whose ingest fails the test if it is ever started."""
    from calibproj.ingest import videos as ingest

    def forbidden(*args, **kwargs):
        raise AssertionError("the ingest started before the output was checked")

    monkeypatch.setattr(ingest, "ingest", forbidden)
    videos = tmp_path / "videos"
    videos.mkdir()
    (videos / "cam1.mp4").write_bytes(b"")
    return [str(videos), "--sequence", str(tmp_path / "sequence.json")]


def test_calibrate_checks_its_output_before_the_ingest(small: Path, tmp_path: Path, no_ingest, capsys) -> None:
    base = ["calibrate", *no_ingest, "--intrinsics", str(small / "intrinsics"), "--no-progress", "--out"]
    a_file = tmp_path / "results.txt"
    a_file.write_text("x")
    assert main([*base, str(a_file)]) == 2
    assert one_error_line(capsys) == f"calibproj calibrate: error: {a_file}: exists and is not a folder"

    holder = OutputFolder(tmp_path / "busy").open()
    assert main([*base, str(tmp_path / "busy")]) == 1
    assert "another calibproj run is writing it" in one_error_line(capsys)
    holder.abort()

    assert main([*base, str(a_file / "results")]) == 2
    assert one_error_line(capsys) == f"calibproj calibrate: error: {a_file / 'results'}: {a_file} is not a folder"


def test_calibrate_into_a_read_only_folder(small: Path, tmp_path: Path) -> None:
    videos = tmp_path / "videos"
    videos.mkdir()
    (videos / "cam1.mp4").write_bytes(b"")  # never read: the output is checked first
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    command = [sys.executable, "-m", "calibproj", "calibrate", str(videos), "--sequence", str(tmp_path / "sequence.json"),
               "--intrinsics", str(small / "intrinsics"), "--out", str(locked / "results")]
    try:
        result = subprocess.run(without_privileges(command), capture_output=True, text=True, timeout=300)
    finally:
        locked.chmod(0o755)
    assert result.returncode == 2, result.stderr
    assert result.stderr.strip() == (f"calibproj calibrate: error: {locked / 'results'}: cannot write in {locked} "
                                     f"(permission denied)")


def test_calibrate_interrupted_or_failing_keeps_the_previous_results(small: Path, tmp_path: Path, capsys,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "results"
    assert main(calibrate_args(small, out, "--no-report")) == 0
    before = snapshot(out)
    capsys.readouterr()

    import calibproj.report

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(calibproj.report, "write_report", interrupted)
    assert main(calibrate_args(small, out, "--force")) == 130
    assert "interrupted" in one_error_line(capsys)
    assert snapshot(out) == before and siblings(out) == []

    calls = []

    def disk_full(staging, folder, record):  # provenance.json, the first file written
        calls.append(staging)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(staging / "provenance.json"))

    monkeypatch.setattr(pipeline, "write_provenance", disk_full)
    assert main(calibrate_args(small, out, "--force", "--no-report")) == 2
    assert one_error_line(capsys) == (f"calibproj calibrate: error: {out}: cannot write the output "
                                      f"(No space left on device)")
    assert len(calls) == 1 and snapshot(out) == before and siblings(out) == []


def test_a_file_the_core_cannot_write_is_an_os_error_naming_it(small: Path, tmp_path: Path) -> None:
    """The results files are written by the C++ core: a write it cannot make reaches
    Python as OSError with the system's errno and the path, as open() raises it."""
    from calibproj.registration.driver import register
    from calibproj.formats.intrinsics import load_intrinsics_dir
    from calibproj.formats.tracks import Tracks

    calibration = register(Tracks.read(small / "tracks.json"), load_intrinsics_dir(small / "intrinsics"))
    blocked = tmp_path / "blocked"
    blocked.write_text("a file where the results folder should be")
    with pytest.raises(OSError) as error:
        calibration.save(blocked)
    assert error.value.errno in (errno.EEXIST, errno.ENOTDIR) and str(blocked) in str(error.value)


def test_a_file_is_never_written_over_a_device_a_pipe_or_a_folder(small: Path, tmp_path: Path) -> None:
    """Files are written whole and moved into place, which replaces whatever is at the
    path: the core fuzz test's "/dev/null" turned the machine's /dev/null into a plain
    file (as root). Both writers (Python's and the core's) now refuse, naming the path."""
    from calibproj import _core
    from calibproj.formats.intrinsics import load_intrinsics_dir

    pipe = tmp_path / "pipe"
    os.mkfifo(pipe)
    folder = tmp_path / "folder"
    folder.mkdir()
    intrinsics = load_intrinsics_dir(small / "intrinsics")
    for target in (pipe, folder):
        with pytest.raises(OSError, match=str(target)) as error:
            jsonio.atomic_write_text(target, "text")
        assert error.value.errno == errno.EEXIST
        with pytest.raises(OSError, match=str(target)) as error:
            _core.formats.write_intrinsics(target, next(iter(intrinsics.values())))
        assert error.value.errno == errno.EEXIST
    assert pipe.is_fifo() and folder.is_dir() and not any(folder.iterdir())


def test_simulate_and_generate_write_their_folders_the_same_way(tmp_path: Path, capsys) -> None:
    sim = tmp_path / "sim"
    simulate = ["simulate", "--scene", "small", "--tracks-only", "--arrays", "4", "--eval-points", "20",
                "--eval-points-per-camera", "5", "--out", str(sim)]
    assert main(simulate) == 0
    (sim / "stale.txt").write_text("from before")
    capsys.readouterr()
    assert main(simulate) == 2
    assert f"{sim}: already holds results (truth.json, scene.json); use --force" in one_error_line(capsys)
    assert main([*simulate, "--force"]) == 0
    assert not (sim / "stale.txt").exists() and (sim / "truth.json").is_file()

    seq = tmp_path / "seq"
    generate = ["generate", "--out", str(seq), "--projector", "480x270", "--grid", "2x4", "--arrays", "2",
                "--scales", "1,2", "--no-video", "--no-progress"]
    assert main([*generate, "--png"]) == 0
    assert (seq / "patterns").is_dir()
    capsys.readouterr()
    assert main(generate) == 2
    assert "use --force" in one_error_line(capsys)
    assert main([*generate, "--force"]) == 0
    assert sorted(p.name for p in seq.iterdir()) == ["sequence.json"]
    assert siblings(seq) == [] and siblings(sim) == []


def test_detect_checks_its_output_file_before_the_ingest(small: Path, tmp_path: Path, no_ingest, capsys) -> None:
    base = ["detect", *no_ingest, "--intrinsics", str(small / "intrinsics"), "--no-progress", "--out"]
    assert main([*base, str(tmp_path)]) == 2
    assert f"{tmp_path}: is a folder" in one_error_line(capsys)
    holder = OutputFile(tmp_path / "tracks.json").open()
    assert main([*base, str(tmp_path / "tracks.json")]) == 1
    assert "another calibproj run is writing it" in one_error_line(capsys)
    holder.close()


def test_messages_made_while_writing_name_the_final_folders(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """The demo's folder holds the results' staging folder: a message naming a file in
    either names it where it is once both are committed, and only while they are written."""
    caplog.set_level(logging.INFO)
    logger = logging.getLogger("calibproj.test_output_folder")
    outer = OutputFolder(tmp_path / "demo").open()
    with outer, outer.writing() as staging:
        inner = OutputFolder(staging / "results").open()
        with inner, inner.writing() as results:
            logger.info("report written: %s", results / "report.html")
            logger.info("videos in %s", staging / "room")
        logger.info("results in %s", staging / "results")
    logger.info("staging was %s", staging)
    final = tmp_path / "demo"
    assert caplog.messages == [f"report written: {final / 'results' / 'report.html'}", f"videos in {final / 'room'}",
                               f"results in {final / 'results'}", f"staging was {staging}"]
    assert (final / "results").is_dir()
