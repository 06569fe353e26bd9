"""The command line itself: --version, did-you-mean hints, the scale's cameras checked
before the ingest, and one exit-status convention (README, "Exit status")."""

from __future__ import annotations

import re
from importlib import metadata
from pathlib import Path

import pytest

import calibproj
from calibproj import version
from calibproj.cli.main import EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_OK, EXIT_USAGE, main

REPO = Path(__file__).resolve().parents[1]


def usage_error(capsys: pytest.CaptureFixture, argv: list[str]) -> str:
    """The error line of an invocation argparse refuses (exit status 2)."""
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == EXIT_USAGE
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[0].startswith("usage: ")
    return lines[-1]


# -- --version -----------------------------------------------------------------------------------


def test_version_comes_from_pyproject(capsys: pytest.CaptureFixture) -> None:
    tomllib = pytest.importorskip("tomllib")  # Python 3.11
    expected = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["version"]
    with pytest.raises(SystemExit) as exit_info:
        main(["--version"])
    assert exit_info.value.code == EXIT_OK
    assert capsys.readouterr().out.strip() == f"calibproj {expected}"
    assert calibproj.__version__ == expected


def test_version_prefers_the_installed_metadata(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(metadata, "version", lambda name: "7.8.9")
    assert version.package_version() == "7.8.9"

    def not_installed(name):
        raise metadata.PackageNotFoundError(name)

    monkeypatch.setattr(metadata, "version", not_installed)
    pyproject = tmp_path / "pyproject.toml"
    pyproject.write_text('[build-system]\nversion = "1"\n\n[project]\nname = "x"\nversion = "2.3.4"\n\n'
                         '[tool.x]\nversion = "5"\n')
    monkeypatch.setattr(version, "PYPROJECT", pyproject)
    assert version.package_version() == "2.3.4"
    monkeypatch.setattr(version, "PYPROJECT", tmp_path / "absent.toml")
    assert version.package_version() == version.UNKNOWN


# -- did you mean ---------------------------------------------------------------------------------


def test_a_mistyped_subcommand_gets_a_suggestion(capsys: pytest.CaptureFixture) -> None:
    line = usage_error(capsys, ["calbrate", "--out", "x"])
    assert "invalid choice: 'calbrate'" in line and line.endswith("(did you mean 'calibrate'?)")
    assert "did you mean 'evaluate'?" in usage_error(capsys, ["evalute"])
    assert "did you mean" not in usage_error(capsys, ["xyzzy"])


def test_a_mistyped_option_gets_a_suggestion(capsys: pytest.CaptureFixture) -> None:
    base = ["calibrate", "--tracks", "t.json", "--intrinsics", "i", "--out", "o"]
    line = usage_error(capsys, [*base, "--forse"])
    assert line == "calibproj calibrate: error: unrecognized arguments: --forse (did you mean --force?)"
    assert usage_error(capsys, [*base, "--scael=camera-height:cam1=2"]).endswith("(did you mean --scale?)")
    # A mistyped required option: argparse says it is missing; the hint names the typo.
    line = usage_error(capsys, ["calibrate", "--tracks", "t.json", "--intrinsics", "i", "--otu", "o"])
    assert "required: --out" in line and line.endswith("(--otu: did you mean --out?)")
    # Options of the program before the subcommand, and of a subcommand after it.
    assert usage_error(capsys, ["--vrebose", "compare", "a", "b"]).endswith("(did you mean --verbose?)")
    assert usage_error(capsys, ["compare", "a", "b", "--jsno"]).endswith("(did you mean --json?)")
    assert "did you mean" not in usage_error(capsys, [*base, "--zzzzzz"])


def test_an_option_of_another_command_is_named_as_such(capsys: pytest.CaptureFixture) -> None:
    line = usage_error(capsys, ["check", "results", "--board", "chessboard:9x6"])
    assert line.endswith("(--board is an option of calibproj intrinsics)")
    line = usage_error(capsys, ["compare", "a", "b", "--pnp-threshold-px", "2"])
    assert line.endswith("(--pnp-threshold-px is an option of calibproj calibrate and capture)")


def test_calibrate_takes_the_ingest_options_of_its_videos() -> None:
    """calibrate ingests videos as detect does, so it takes detect's knobs (found by a
    user: --min-correlation was answered with "did you mean --min-coverage?")."""
    from calibproj.cli.main import build_parser, parse_arguments
    from calibproj.cli.calibrate import INGEST_OPTIONS_NOT_HERE
    from calibproj.cli.options import dataclass_changed_from_args
    from calibproj.ingest.options import IngestOptions

    parser = build_parser()
    args = parse_arguments(parser, ["calibrate", "videos", "--out", "o", "--min-correlation", "0.7",
                                    "--detector-option", "quad_decimate=2"])
    options = dataclass_changed_from_args(IngestOptions, args, exclude=INGEST_OPTIONS_NOT_HERE)
    assert options == IngestOptions(min_correlation=0.7) and args.detector_option == ["quad_decimate=2"]
    plain = parse_arguments(parser, ["calibrate", "videos", "--out", "o"])
    assert dataclass_changed_from_args(IngestOptions, plain, exclude=INGEST_OPTIONS_NOT_HERE) is None


def every_command_parser() -> dict:
    from calibproj.cli.main import build_parser

    parser = build_parser()
    commands = next(action.choices for action in parser._actions if isinstance(action.choices, dict))
    return {"calibproj": parser, **commands}


def test_every_option_has_help_and_every_usage_fits_a_line() -> None:
    for name, parser in every_command_parser().items():
        for action in parser._actions:
            assert action.help and action.help.strip(), (name, action.option_strings or action.dest)
        usage = parser.format_usage().strip()
        assert "\n" not in usage and len(usage) <= 100, usage
        if name != "calibproj":
            assert usage.endswith("[options]"), usage


def test_common_options_come_first_and_the_rest_in_groups(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        main(["calibrate", "--help"])
    text = capsys.readouterr().out
    groups = re.findall(r"^(\S[^\n]*):$", text.split("positional arguments:")[1], re.MULTILINE)
    assert groups[:2] == ["options", "output and progress"]
    assert {"registration options", "ingest options (with videos; as calibproj detect)"} <= set(groups)
    common = text.split("\noptions:\n")[1].split("\n\n")[0]
    assert all(flag in common for flag in ("--sequence", "--intrinsics", "--out", "--scale", "--export"))
    assert "--pnp-threshold-px" not in common and "--min-correlation" not in common


def test_verbose_is_taken_after_the_command_too(capsys: pytest.CaptureFixture) -> None:
    from calibproj.cli.main import build_parser, parse_arguments

    for line in (["-v", "compare", "a", "b"], ["compare", "a", "b", "-v"], ["compare", "-v", "a", "b"]):
        args = parse_arguments(build_parser(), line)
        assert args.verbose + args.command_verbose == 1, line
    args = parse_arguments(build_parser(), ["-v", "demo", "-v"])
    assert args.verbose + args.command_verbose == 2


def test_every_command_that_replaces_a_folder_says_force_alike() -> None:
    for name, parser in every_command_parser().items():
        flags = {flag for action in parser._actions for flag in action.option_strings}
        assert "--no-force" not in flags, name


# -- the scale's cameras, before the ingest ------------------------------------------------------------


@pytest.fixture
def videos(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Two cameras' videos (empty files), and an ingest that fails the test if started."""
    from calibproj.ingest import videos as ingest

    def forbidden(*args, **kwargs):
        raise AssertionError("the ingest started before the scale was checked")

    monkeypatch.setattr(ingest, "ingest", forbidden)
    folder = tmp_path / "videos"
    folder.mkdir()
    for name in ("far1", "far2", "notes.txt"):
        (folder / (name if "." in name else f"{name}.mp4")).write_bytes(b"")
    (tmp_path / "intrinsics").mkdir()
    return folder


@pytest.mark.parametrize("scale, message", [
    ("camera-height:fra1=2.5", "no camera 'fra1' (cameras: far1, far2; did you mean far1?)"),
    ("camera-height:notes=2.5", "no camera 'notes' (cameras: far1, far2)"),
    ("distance:far1,far22=1.5", "no camera 'far22' (cameras: far1, far2; did you mean far2?)"),
])
def test_scale_cameras_are_checked_against_the_videos_before_the_ingest(
        videos: Path, tmp_path: Path, capsys: pytest.CaptureFixture, scale: str, message: str) -> None:
    status = main(["calibrate", str(videos), "--sequence", str(tmp_path / "sequence.json"), "--intrinsics",
                   str(tmp_path / "intrinsics"), "--out", str(tmp_path / "results"), "--scale", scale])
    assert status == EXIT_USAGE
    error = capsys.readouterr().err.strip()
    assert error == f"calibproj calibrate: error: scale measurement {scale!r}: {message}"
    assert not (tmp_path / "results").exists()


@pytest.mark.parametrize("extra, message", [
    (["--exposure", "far3=0.01"], "exposures given for camera(s) without a video: far3"),
    (["--exposure", "far1=fast"], "--exposure expects CAMERA=SECONDS with 0 < SECONDS <= 1, got 'far1=fast'"),
    (["--exposure", "far1=0"], "--exposure expects CAMERA=SECONDS with 0 < SECONDS <= 1, got 'far1=0'"),
    # Found by probing: infinity passed this check and failed after the ingest, and 10 s
    # (no video camera's frame) was taken by one tool and not the other.
    (["--exposure", "far1=inf"], "--exposure expects CAMERA=SECONDS with 0 < SECONDS <= 1, got 'far1=inf'"),
    (["--exposure", "far1=10"], "--exposure expects CAMERA=SECONDS with 0 < SECONDS <= 1, got 'far1=10'"),
])
def test_exposures_are_checked_before_the_ingest(videos: Path, tmp_path: Path, capsys: pytest.CaptureFixture,
                                                 extra: list[str], message: str) -> None:
    status = main(["calibrate", str(videos), "--sequence", str(tmp_path / "sequence.json"), "--intrinsics",
                   str(tmp_path / "intrinsics"), "--out", str(tmp_path / "results"), *extra])
    assert status == EXIT_USAGE
    assert capsys.readouterr().err.strip() == f"calibproj calibrate: error: {message}"
    assert not (tmp_path / "results").exists()


def test_exposures_apply_to_videos_only(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    status = main(["calibrate", "--tracks", str(tmp_path / "tracks.json"), "--intrinsics", str(tmp_path),
                   "--out", str(tmp_path / "results"), "--exposure", "far1=0.01"])
    assert status == EXIT_USAGE
    assert capsys.readouterr().err.strip() == "calibproj calibrate: error: --exposure applies to videos, not to --tracks"


# -- exit status --------------------------------------------------------------------------------------


def interrupt_inside(error: Exception) -> Exception:
    """``error`` as Python raises it when a KeyboardInterrupt lands inside an import or
    while a class is made."""
    error.__cause__ = KeyboardInterrupt()
    return error


INTERRUPTS_IN_DISGUISE = [
    interrupt_inside(RuntimeError("Error calling __set_name__ on 'Field' instance 'scales' in 'DemoOptions'")),
    interrupt_inside(ImportError("initialization failed")),
]


@pytest.mark.parametrize("raised", INTERRUPTS_IN_DISGUISE)
def test_an_interrupt_while_the_commands_are_imported_gives_one_line(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture, raised: Exception) -> None:
    """Found by probing Ctrl-C at 0.8 s: a dataclass being made turned it into a
    RuntimeError, which printed a traceback."""
    from calibproj.cli import main as cli

    def build_parser():
        raise raised

    monkeypatch.setattr(cli, "build_parser", build_parser)
    assert main(["compare", "a.json", "b.json"]) == EXIT_INTERRUPTED
    assert capsys.readouterr().err.strip().splitlines() == ["calibproj: interrupted"]


@pytest.mark.parametrize("raised, status, line", [
    *[(error, EXIT_INTERRUPTED, "interrupted") for error in INTERRUPTS_IN_DISGUISE],
    (ValueError("sequence.json: not a sequence"), EXIT_USAGE, "error: sequence.json: not a sequence"),
    (FileNotFoundError("a.json: no such file"), EXIT_USAGE, "error: a.json: no such file"),
    (RuntimeError("ffmpeg not found on PATH"), EXIT_FAILURE, "error: ffmpeg not found on PATH"),
    (KeyboardInterrupt(), EXIT_INTERRUPTED, "interrupted"),
    (KeyError("cam9"), EXIT_FAILURE, "internal error: KeyError: 'cam9'"),
])
def test_one_exit_status_convention(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture,
                                    raised: BaseException, status: int, line: str) -> None:
    from calibproj.cli import compare

    def run(args):
        raise raised

    monkeypatch.setattr(compare, "run", run)
    assert main(["compare", "a.json", "b.json"]) == status
    error = capsys.readouterr().err.strip().splitlines()
    assert error[-1] == f"calibproj compare: {line}"
    # Only an internal error (a bug) shows its traceback.
    assert (error[0] == "Traceback (most recent call last):") == (status == EXIT_FAILURE and "internal" in line)
    assert len(error) == 1 or "internal" in line


@pytest.mark.parametrize("signal_name", ["SIGTERM", "SIGINT"])
def test_an_interruption_swallowed_by_other_code_is_still_one(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture, signal_name: str) -> None:
    """Found by sending SIGTERM at the moment the staging folder appeared, 150 times: 2
    runs went to their end (OpenCV's loader swallowed the KeyboardInterrupt) and 2
    printed a traceback (pybind11 turned it into a TypeError while converting a path)."""
    import os
    import signal
    import time

    from calibproj.cli import compare

    def run(args):
        try:  # as a bare ``except:`` in a library does
            os.kill(os.getpid(), getattr(signal, signal_name))
            time.sleep(1.0)
        except BaseException:
            pass
        raise TypeError("read_sequence(): incompatible function arguments")

    monkeypatch.setattr(compare, "run", run)
    assert main(["compare", "a.json", "b.json"]) == EXIT_INTERRUPTED
    assert capsys.readouterr().err.strip().splitlines() == ["calibproj compare: interrupted"]
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # the handler is gone with the run


def test_readme_documents_the_exit_status() -> None:
    readme = (REPO / "README.md").read_text()
    section = re.search(r"^## Exit status\n(.*?)(?=^## )", readme, re.MULTILINE | re.DOTALL)
    assert section, "README has no Exit status section"
    for code in (EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_INTERRUPTED):
        assert re.search(rf"^- `{code}`", section.group(1), re.MULTILINE), code


def test_ctrl_c_at_any_moment_of_the_start_gives_one_line(tmp_path: Path) -> None:
    """Found by probing: Ctrl-C in the first 0.3 s (while the package was imported)
    printed a traceback."""
    import signal
    import subprocess
    import sys
    import time

    for index, delay in enumerate((0.02, 0.05, 0.1, 0.15, 0.2, 0.3, 0.5, 0.8)):
        # A small projection: a run whose signal came before the interpreter could take
        # it goes to its end (EXIT_OK), which should not take minutes.
        process = subprocess.Popen([sys.executable, "-m", "calibproj", "generate", "--arrays", "2", "--scales", "1,2",
                                    "--out", str(tmp_path / str(index))],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        time.sleep(delay)
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=120)
        if "Fatal Python error: init_import_site" in stderr or "Could not import runpy module" in stderr:
            # The interpreter's own start, before any of the package runs (its frames may
            # name an editable install's import hook, which site runs; -m needs runpy,
            # whose import the signal can end with exit status 1).
            continue
        # The interpreter's own start (its import machinery) may still report the signal
        # it could not deliver ("Exception ignored in ..."); no frame of the package may.
        assert 'calibproj' not in "".join(line for line in stderr.splitlines() if line.strip().startswith("File ")), \
            (delay, stderr)
        # Before the interpreter has its handler the signal ends it as it ends any program.
        assert process.returncode in (EXIT_INTERRUPTED, -signal.SIGINT, EXIT_OK), (delay, stderr)
        if process.returncode == EXIT_INTERRUPTED:
            assert stderr.strip().splitlines()[-1].endswith("interrupted"), (delay, stderr)
