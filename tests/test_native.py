"""The standalone executable calibproj-native against the Python command line."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from calibproj.sequence import generate
from calibproj.ingest.options import IngestOptions
from calibproj.registration.driver import RegistrationOptions
from calibproj.simulate import simulate_tracks
from calibproj.simulate.render import simulate_videos

REPO = Path(__file__).resolve().parents[1]


def find_native() -> Path:
    """The installed executable (next to this interpreter), else the developer build."""
    candidates = [
        Path(sys.executable).parent / "calibproj-native",
        Path(shutil.which("calibproj-native") or "/nonexistent"),
        REPO / "build" / "dev" / "cpp" / "app" / "calibproj-native",
    ]
    for candidate in candidates:
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return candidate
    raise FileNotFoundError(f"calibproj-native not found in {[str(c) for c in candidates]}")


NATIVE = find_native()


def run_python(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "calibproj", *args], capture_output=True, text=True)


def run_native(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([str(NATIVE), *args], capture_output=True, text=True, env=env)


@pytest.fixture(scope="module")
def simulation(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("sim")
    simulate_tracks("paper", out, noise_px=0.5, seed=11, outlier_fraction=0.02)
    return out


CALIBRATION_FILES = ["camera_poses.json", "metrics.json", "points.ply", "uncertainty.json"]
EXPORT_FILES = ["calibration_opencv.yaml", "calibration.toml", "colmap/cameras.txt", "colmap/images.txt",
                "colmap/points3D.txt"]


def assert_same_bytes(a: Path, b: Path, names: list[str]) -> None:
    """The files of both folders byte for byte; provenance.json as assert_same_provenance."""
    for name in names:
        if name == "provenance.json":
            assert_same_provenance(a, b)
        else:
            assert (a / name).read_bytes() == (b / name).read_bytes(), name


def files_below(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


@pytest.mark.parametrize("model", ["coplanar", "free"])
def test_native_and_python_give_the_same_calibration(simulation: Path, tmp_path: Path, model: str) -> None:
    common = ["--tracks", str(simulation / "tracks.json"), "--intrinsics", str(simulation / "intrinsics"),
              "--model", model, "--json"]
    python = run_python("calibrate", *common, "--out", str(tmp_path / "python"), "--no-report")
    assert python.returncode == 0, python.stderr
    # No Python on PATH: the executable needs none.
    native = run_native("calibrate", *common, "--out", str(tmp_path / "native"), env={"PATH": "/nonexistent"})
    assert native.returncode == 0, native.stderr
    # One C++ writer and a registration that repeats to the last bit: the same bytes, and
    # the same summary printed.
    assert_same_bytes(tmp_path / "python", tmp_path / "native", CALIBRATION_FILES)
    assert native.stdout == python.stdout
    rows = json.loads(native.stdout)
    assert len(rows) == 10 and {row["status"] for row in rows} <= {"reference", "ok", "weak"}
    poses = json.loads((tmp_path / "native" / "camera_poses.json").read_text())
    assert poses["unit"] == "arbitrary" and len(poses["cameras"]) == 10


def assert_same_provenance(python: Path, native: Path) -> None:
    """Both provenance.json the core's: the same record but for when and by which command
    it was made, and the Python version Python adds."""
    documents = [json.loads((folder / "provenance.json").read_text()) for folder in (python, native)]
    assert documents[0]["command"][0] == "calibproj" and documents[1]["command"][0] == "calibproj-native"
    assert "python" in documents[0] and "python" not in documents[1]
    for document in documents:
        for key in ("created", "command", "python"):
            document.pop(key, None)
    assert documents[0] == documents[1]
    assert documents[1]["options"] and documents[1]["inputs"]["source"]["path"]


def test_native_scales_and_exports_as_python_does(simulation: Path, tmp_path: Path) -> None:
    common = ["--tracks", str(simulation / "tracks.json"), "--intrinsics", str(simulation / "intrinsics"),
              "--scale", "distance:far1,near2=3.25", "--export", "anipose,yaml,colmap,yaml"]
    python = run_python("calibrate", *common, "--out", str(tmp_path / "python"), "--no-report")
    assert python.returncode == 0, python.stderr
    native = run_native("calibrate", *common, "--out", str(tmp_path / "native"))
    assert native.returncode == 0, native.stderr
    # Every file of both folders: the results, the exports, and the tracks and intrinsics
    # they came from, and where they came from.
    written = files_below(tmp_path / "native")
    assert set(CALIBRATION_FILES + EXPORT_FILES + ["tracks.json", "intrinsics/far1.json"]) <= set(written)
    assert files_below(tmp_path / "python") == written
    assert_same_bytes(tmp_path / "python", tmp_path / "native", written)
    poses = json.loads((tmp_path / "native" / "camera_poses.json").read_text())
    centres = {name: np.array(pose["center"]) for name, pose in poses["cameras"].items()}
    assert poses["unit"] == "m"
    assert np.linalg.norm(centres["far1"] - centres["near2"]) == pytest.approx(3.25, rel=1e-12)
    assert "results in" in native.stdout and "(unit: m)" in native.stdout


def test_native_refines_intrinsics_as_python_does(simulation: Path, tmp_path: Path) -> None:
    """Both tools run the core's self-calibration and write the same bytes: the entries
    refined and held and why, the refined intrinsics, the tracks re-expressed with them,
    the poses. The focal lengths are given 5 % off."""
    from calibproj.formats.intrinsics import Intrinsics, load_intrinsics_dir, write_intrinsics_dir
    from calibproj.selfcal.lenses import convert_tracks
    from calibproj.formats.tracks import Tracks

    truth = load_intrinsics_dir(simulation / "intrinsics")
    given = {name: Intrinsics(name, i.resolution, np.diag([1.05, 1.05, 1.0]) @ i.K, i.dist) for name, i in truth.items()}
    write_intrinsics_dir(tmp_path / "given", given)
    convert_tracks(Tracks.read(simulation / "tracks.json"), truth, given).write(tmp_path / "tracks.json")
    common = ["--tracks", str(tmp_path / "tracks.json"), "--intrinsics", str(tmp_path / "given"),
              "--refine-intrinsics", "focal,k1,k2", "--refine-intrinsics", "far1=none", "--rounds", "1"]
    python = run_python("calibrate", *common, "--out", str(tmp_path / "python"), "--no-report")
    assert python.returncode == 0, python.stderr
    native = run_native("calibrate", *common, "--out", str(tmp_path / "native"))
    assert native.returncode == 0, native.stderr
    written = files_below(tmp_path / "native")
    assert files_below(tmp_path / "python") == written
    assert_same_bytes(tmp_path / "python", tmp_path / "native", written)
    reports = json.loads((tmp_path / "native" / "self_calibration.json").read_text())
    assert reports["options"]["rounds"] == 1
    assert "far1" not in reports["cameras"] and len(reports["cameras"]) == 9
    refined = load_intrinsics_dir(tmp_path / "native" / "intrinsics")
    focal_refined = [name for name, report in reports["cameras"].items() if "focal" in report["refined"]]
    assert focal_refined and all(refined[name].K[0, 0] != given[name].K[0, 0] for name in focal_refined)


def test_native_refuses_a_bad_refinement_request_in_one_line(simulation: Path, tmp_path: Path) -> None:
    common = ["--tracks", str(simulation / "tracks.json"), "--intrinsics", str(simulation / "intrinsics")]
    for request, message in (("focal,k9", "unknown entry 'k9'"), ("nobody=focal", "no camera named 'nobody'")):
        native = run_native("calibrate", *common, "--out", str(tmp_path / "out"), "--refine-intrinsics", request)
        assert native.returncode == 2 and message in native.stderr and len(native.stderr.strip().splitlines()) == 1
        assert not (tmp_path / "out" / "camera_poses.json").exists()
    native = run_native("calibrate", *common, "--out", str(tmp_path / "out"), "--refine-intrinsics", "focal",
                        "--rounds", "0")
    assert native.returncode == 2 and "rounds must be a positive number" in native.stderr


def test_native_capture_checks_its_refinement_before_recording(tmp_path: Path) -> None:
    """A bad request, or one with --check, is refused before the site file is even read."""
    site = str(tmp_path / "no-site.json")
    bad = run_native("capture", site, "--out", str(tmp_path / "out"), "--refine-intrinsics", "focal,k9")
    assert bad.returncode == 2 and "unknown entry 'k9'" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1
    check = run_native("capture", site, "--check", str(tmp_path), "--sequence", site, "--refine-intrinsics", "focal")
    assert check.returncode == 2 and "are for calibrating, not with --check" in check.stderr
    assert not (tmp_path / "out").exists()


def test_fuzzed_refinement_requests_give_one_line(simulation: Path, tmp_path: Path) -> None:
    """Requests of random pieces (entries, names, separators, control and non-ASCII
    characters) and random knob values: status 2 with one error line, never a crash. The
    output folder exists (no --force): a request that parses stops there, before any work."""
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "camera_poses.json").write_text("{}")
    common = ["calibrate", "--tracks", str(simulation / "tracks.json"), "--intrinsics", str(simulation / "intrinsics"),
              "--out", str(tmp_path / "out")]
    rng = np.random.default_rng(7)
    pieces = ["focal", "pp", "k1", "k2", "k3", "tangential", "none", "far1", "*", ",", ",", "=", "==", " ", "\t",
              "k9", "\u00e9", "\x7f", "-", "--rounds", ""]
    knobs = ["--rounds", "--min-coverage", "--max-focal-sigma", "--lens-solver-iterations", "--min-chi2-drop"]
    values = ["0", "-1", "nan", "inf", "1e308", "1e-320", "abc", "", "2", "0.5"]
    for _ in range(40):
        request = "".join(rng.choice(pieces, size=rng.integers(0, 6)))
        extra = [str(rng.choice(knobs)), str(rng.choice(values))] if rng.random() < 0.5 else []
        result = subprocess.run([str(NATIVE), *common, "--refine-intrinsics", request, *extra], capture_output=True,
                                timeout=60)
        # One line saying what is wrong (a value the command line cannot convert adds the
        # parser's usual hint to --help).
        said = [line for line in result.stderr.decode(errors="replace").strip().splitlines()
                if line != "Run with --help for more information."]
        assert result.returncode == 2 and len(said) == 1, (request, extra, said)


def test_intrinsics_without_an_image_size_are_kept_in_the_results(simulation: Path, tmp_path: Path) -> None:
    """The reference code's JSON gives no image size: both tools calibrate with it and
    keep it in results/intrinsics with resolution null (both used to fail at the end)."""
    reference = tmp_path / "reference"
    reference.mkdir()
    for path in sorted((simulation / "intrinsics").glob("*.json")):
        ours = json.loads(path.read_text())
        document = {"sensors": {"RGB": {"intrinsics": {"data": np.ravel(ours["K"]).tolist()},
                                        "distortionCoefficients": {"data": ours["dist"]}}}}
        (reference / path.name).write_text(json.dumps(document))
    common = ["--tracks", str(simulation / "tracks.json"), "--intrinsics", str(reference)]
    python = run_python("calibrate", *common, "--out", str(tmp_path / "python"), "--no-report")
    native = run_native("calibrate", *common, "--out", str(tmp_path / "native"))
    assert python.returncode == 0 and native.returncode == 0, (python.stderr, native.stderr)
    kept = json.loads((tmp_path / "native" / "intrinsics" / "far1.json").read_text())
    assert kept["resolution"] is None and kept["K"] == json.loads((simulation / "intrinsics" / "far1.json").read_text())["K"]
    assert_same_bytes(tmp_path / "python", tmp_path / "native", files_below(tmp_path / "native"))
    evaluated = run_python("evaluate", str(tmp_path / "native"), "--tracks", str(simulation / "eval_tracks.json"))
    assert evaluated.returncode == 0, evaluated.stderr


def test_when_no_camera_registers_both_write_the_failures_and_no_export(simulation: Path, tmp_path: Path) -> None:
    intrinsics = tmp_path / "intrinsics"
    intrinsics.mkdir()
    shutil.copy(simulation / "intrinsics" / "far1.json", intrinsics / "other.json")  # nobody's
    common = ["--tracks", str(simulation / "tracks.json"), "--intrinsics", str(intrinsics), "--export", "yaml"]
    python = run_python("calibrate", *common, "--out", str(tmp_path / "python"), "--no-report")
    native = run_native("calibrate", *common, "--out", str(tmp_path / "native"))
    assert python.returncode == 1 and native.returncode == 1, (python.stderr, native.stderr)
    assert "nothing exported" in python.stderr and "nothing exported" in native.stderr
    written = files_below(tmp_path / "native")
    assert "calibration_opencv.yaml" not in written and "metrics.json" in written
    assert_same_bytes(tmp_path / "python", tmp_path / "native", written)
    metrics = json.loads((tmp_path / "native" / "metrics.json").read_text())
    assert all(camera["failure"] for camera in metrics["cameras"].values()) and len(metrics["cameras"]) == 10


def test_native_scale_errors_match_python(simulation: Path, tmp_path: Path) -> None:
    tracks, intrinsics = str(simulation / "tracks.json"), str(simulation / "intrinsics")
    cases = [["--scale", "camera-height:far7=2.5"], ["--scale", "height:far1=2"], ["--scale", "distance:far1=2"],
             ["--scale", "marker-size:0.2"], ["--scale", "camera-height:far1=-1"], ["--export", "yaml,ply"]]
    for k, case in enumerate(cases):
        args = ["--tracks", tracks, "--intrinsics", intrinsics, *case]
        python = run_python("calibrate", *args, "--out", str(tmp_path / f"python{k}"))
        native = run_native("calibrate", *args, "--out", str(tmp_path / f"native{k}"))
        assert python.returncode == 2 and native.returncode == 2, (case, python.stderr, native.stderr)
        assert error_line(native) == error_line(python), case
        assert not (tmp_path / f"native{k}").exists()
    assert "did you mean far1?" in error_line(native_run := run_native(
        "calibrate", "--tracks", tracks, "--intrinsics", intrinsics, "--scale", "camera-height:fra1=2",
        "--out", str(tmp_path / "typo")))
    assert native_run.returncode == 2


def error_line(result: subprocess.CompletedProcess) -> str:
    """The message after 'error: ' of the one-line error report."""
    lines = [line for line in result.stderr.splitlines() if ": error: " in line]
    assert len(lines) == 1, result.stderr
    return lines[0].split(": error: ", 1)[1]


def test_bad_inputs_fail_with_the_same_messages(simulation: Path, tmp_path: Path) -> None:
    tracks, intrinsics = str(simulation / "tracks.json"), str(simulation / "intrinsics")
    existing = tmp_path / "existing"
    assert run_python("calibrate", "--tracks", tracks, "--intrinsics", intrinsics, "--out", str(existing)).returncode == 0
    cases = [
        ["--tracks", str(tmp_path / "missing.json"), "--intrinsics", intrinsics, "--out", str(tmp_path / "a")],
        ["--tracks", str(simulation / "truth.json"), "--intrinsics", intrinsics, "--out", str(tmp_path / "b")],
        ["--tracks", tracks, "--intrinsics", str(tmp_path / "nowhere"), "--out", str(tmp_path / "c")],
        ["--tracks", tracks, "--intrinsics", intrinsics, "--out", str(existing)],
    ]
    for case in cases:
        python, native = run_python("calibrate", *case), run_native("calibrate", *case)
        assert python.returncode == 2 and native.returncode == 2, (case, python.stderr, native.stderr)
        assert error_line(native) == error_line(python)


def test_native_help_and_unknown_options() -> None:
    assert run_native("--help").returncode == 0
    assert "--tracks" in run_native("calibrate", "--help").stdout
    assert run_native("calibrate", "--no-such-option").returncode != 0
    assert run_native().returncode != 0


@pytest.fixture(scope="module")
def room(tmp_path_factory) -> Path:
    """A short ArUco sequence rendered in the small room (3 cameras)."""
    out = tmp_path_factory.mktemp("room")
    sequence = generate(out / "sequence", markers="aruco:4X4_50", arrays=12, scales=(3.0, 5.0, 8.0), video=False)
    simulate_videos("small", sequence, out / "room", seed=1)
    return out


def detect_args(room: Path, videos: Path, out: Path, intrinsics: Path | None = None) -> list[str]:
    return ["detect", str(videos), "--sequence", str(room / "sequence" / "sequence.json"),
            "--intrinsics", str(intrinsics or room / "room" / "intrinsics"), "--out", str(out / "tracks.json"),
            "--no-progress"]


def timed(run, *args: str) -> tuple[subprocess.CompletedProcess, float]:
    start = time.perf_counter()
    result = run(*args)
    return result, time.perf_counter() - start


def test_native_and_python_detect_the_same_tracks(room: Path, tmp_path: Path) -> None:
    # A camera without intrinsics fails in both and stays in the tracks without observations.
    videos = tmp_path / "videos"
    shutil.copytree(room / "room" / "videos", videos)
    first = sorted(videos.iterdir())[0]
    shutil.copy(first, videos / f"stray{first.suffix}")
    # Two intrinsics files for one camera (.json and .YAML): both tools fail that camera.
    intrinsics = tmp_path / "intrinsics"
    shutil.copytree(room / "room" / "intrinsics", intrinsics)
    doubled = sorted(intrinsics.iterdir())[-1]
    shutil.copy(doubled, doubled.with_suffix(".YAML"))
    # Default options (regions of interest): each pattern is planned from the detections
    # of the patterns before it, absorbed in order, so the result does not depend on
    # thread timing and both commands write the same bytes.
    python, python_s = timed(run_python, *detect_args(room, videos, tmp_path / "python", intrinsics))
    assert python.returncode == 0, python.stderr
    native, native_s = timed(run_native, *detect_args(room, videos, tmp_path / "native", intrinsics))
    assert native.returncode == 0, native.stderr
    print(f"detect on the small room: python {python_s:.2f} s, native {native_s:.2f} s")

    tracks_py = json.loads((tmp_path / "python" / "tracks.json").read_text())
    tracks_cc = json.loads((tmp_path / "native" / "tracks.json").read_text())
    assert tracks_cc["cameras"] == tracks_py["cameras"] and "stray" in tracks_cc["cameras"]
    assert tracks_cc["markers_per_array"] == tracks_py["markers_per_array"]
    assert tracks_cc["observations"].keys() == tracks_py["observations"].keys()
    for name, entry in tracks_py["observations"].items():
        assert tracks_cc["observations"][name]["point_ids"] == entry["point_ids"], name
        np.testing.assert_allclose(np.reshape(tracks_cc["observations"][name]["xy"], (-1, 2)),
                                   np.reshape(entry["xy"], (-1, 2)), rtol=0, atol=1e-9)
    assert tracks_cc["observations"]["stray"]["point_ids"] == []
    assert sum(len(e["point_ids"]) for e in tracks_cc["observations"].values()) > 0
    # The same file, byte for byte, and the same report per camera.
    assert (tmp_path / "native" / "tracks.json").read_text() == (tmp_path / "python" / "tracks.json").read_text()
    report_py = json.loads((tmp_path / "python" / "detect_report.json").read_text())
    report_cc = json.loads((tmp_path / "native" / "detect_report.json").read_text())
    for name, camera in report_py["cameras"].items():
        assert report_cc["cameras"][name]["status"] == camera["status"], name
        assert report_cc["cameras"][name].get("error") == camera.get("error"), name
        assert report_cc["cameras"][name].get("msms_kept") == camera.get("msms_kept"), name
    # The report is built by one C++ function for both: equal but for the times measured.
    for report in (report_py, report_cc):
        for camera in report["cameras"].values():
            camera.pop("seconds", None)
    assert report_cc == report_py
    assert "a second intrinsics file for camera" in report_cc["cameras"][doubled.stem]["error"]
    assert "camera stray: " in native.stderr
    # Written atomically under the lock: no temporary or lock file stays beside them.
    assert sorted(p.name for p in (tmp_path / "native").iterdir()) == ["detect_report.json", "tracks.json"]
    assert python.stdout.splitlines()[-1] == native.stdout.splitlines()[-1]


def test_native_calibrates_the_room_in_metres_as_python_does(room: Path, tmp_path: Path) -> None:
    # Tracks from the native detection; the scale from the projected marker size.
    videos = room / "room" / "videos"
    assert run_native(*detect_args(room, videos, tmp_path / "detected")).returncode == 0
    common = ["--tracks", str(tmp_path / "detected" / "tracks.json"), "--intrinsics", str(room / "room" / "intrinsics"),
              "--sequence", str(room / "sequence" / "sequence.json"), "--scale", "marker-size:0.1",
              "--export", "yaml,colmap,anipose"]
    python = run_python("calibrate", *common, "--out", str(tmp_path / "python"), "--no-report")
    native = run_native("calibrate", *common, "--out", str(tmp_path / "native"))
    assert python.returncode == native.returncode, (python.stderr, native.stderr)
    assert native.returncode in (0, 1), native.stderr  # a camera may fail; the others are written
    assert_same_bytes(tmp_path / "python", tmp_path / "native", CALIBRATION_FILES + EXPORT_FILES)
    poses = json.loads((tmp_path / "native" / "camera_poses.json").read_text())
    assert poses["unit"] == "m" and len(poses["cameras"]) >= 2


def test_native_calibrates_videos_as_python_does(room: Path, tmp_path: Path) -> None:
    """calibrate VIDEOS_DIR in both tools: the same ingest, tracks and calibration, byte
    for byte, a camera whose video is broken reported by both and the others calibrated;
    the native detect report kept in the results."""
    videos = tmp_path / "videos"
    shutil.copytree(room / "room" / "videos", videos)
    (videos / "broken.mp4").write_bytes(b"not a video")
    (tmp_path / "intrinsics").mkdir()
    for file in (room / "room" / "intrinsics").iterdir():
        shutil.copy(file, tmp_path / "intrinsics" / file.name)
    shutil.copy(next((room / "room" / "intrinsics").iterdir()), tmp_path / "intrinsics" / "broken.json")
    common = [str(videos), "--intrinsics", str(tmp_path / "intrinsics"), "--sequence",
              str(room / "sequence" / "sequence.json"), "--scale", "marker-size:0.1", "--no-progress"]
    python = run_python("calibrate", *common, "--out", str(tmp_path / "python"), "--no-report")
    native = run_native("calibrate", *common, "--out", str(tmp_path / "native"))
    assert python.returncode == native.returncode == 1, (python.stderr, native.stderr)
    assert_same_bytes(tmp_path / "python", tmp_path / "native", CALIBRATION_FILES + ["tracks.json"])
    metrics = json.loads((tmp_path / "native" / "metrics.json").read_text())
    assert "broken.mp4" in metrics["cameras"]["broken"]["failure"]
    assert len(json.loads((tmp_path / "native" / "camera_poses.json").read_text())["cameras"]) >= 2
    report = json.loads((tmp_path / "native" / "detect_report.json").read_text())
    assert set(report["cameras"]) == set(metrics["cameras"])
    # Options for videos do not apply to tracks, and one source is given: as in Python.
    tracks = ["--tracks", str(tmp_path / "native" / "tracks.json"), "--intrinsics", str(tmp_path / "intrinsics")]
    for args in ([*tracks, "--exposure", "far1=0.01"], [*tracks, "--no-use-roi"], [*tracks, str(videos)],
                 ["--intrinsics", str(tmp_path / "intrinsics")], [str(videos), "--intrinsics", str(tmp_path)]):
        python = run_python("calibrate", *args, "--out", str(tmp_path / "p"))
        native = run_native("calibrate", *args, "--out", str(tmp_path / "n"))
        assert python.returncode == native.returncode == 2, args
        assert error_line(python) == error_line(native), args


def test_native_starts_cameras_without_intrinsics_from_a_nominal_field_of_view(room: Path, tmp_path: Path) -> None:
    """calibrate VIDEOS_DIR --nominal-fov: a camera without an intrinsics file starts
    from a centred pinhole of that field of view and the video's frame size, refined by
    the self-calibration; both tools give the same files, and refuse the same misuses."""
    videos, sequence = room / "room" / "videos", room / "sequence" / "sequence.json"
    given = tmp_path / "intrinsics"
    given.mkdir()
    first = sorted((room / "room" / "intrinsics").iterdir())[0]
    shutil.copy(first, given / first.name)  # one camera with its file, the others nominal
    common = [str(videos), "--sequence", str(sequence), "--intrinsics", str(given), "--nominal-fov", "60",
              "--refine-intrinsics", "focal", "--no-progress"]
    python = run_python("calibrate", *common, "--out", str(tmp_path / "python"), "--no-report")
    native = run_native("calibrate", *common, "--out", str(tmp_path / "native"))
    assert python.returncode == native.returncode, (python.stderr, native.stderr)
    assert native.returncode in (0, 1), native.stderr
    written = [name for name in files_below(tmp_path / "native") if name != "detect_report.json"]
    assert {"self_calibration.json", "provenance.json", "intrinsics/cam2.json"} <= set(written)
    assert_same_bytes(tmp_path / "python", tmp_path / "native", written)
    assert "deg field of view" in native.stderr
    misuses = [[str(videos), "--sequence", str(sequence), "--nominal-fov", "60"],
               [str(videos), "--sequence", str(sequence), "--refine-intrinsics", "focal"],
               ["--tracks", str(tmp_path / "native" / "tracks.json"), "--nominal-fov", "60", "--refine-intrinsics",
                "focal"],
               [*common[:5], "--nominal-fov", "5", "--refine-intrinsics", "focal"],
               [*common[:5], "--nominal-fov", "nan", "--refine-intrinsics", "focal"]]
    for args in misuses:
        python = run_python("calibrate", *args, "--out", str(tmp_path / "p"))
        native = run_native("calibrate", *args, "--out", str(tmp_path / "n"))
        assert python.returncode == native.returncode == 2, (args, python.stderr, native.stderr)
        assert error_line(python) == error_line(native), args


def test_native_detect_bad_inputs_fail_with_the_same_messages(room: Path, tmp_path: Path) -> None:
    videos = room / "room" / "videos"
    not_a_sequence = tmp_path / "tracks_as_sequence.json"
    not_a_sequence.write_text(json.dumps({"schema": "calibproj.tracks/1"}))
    cases = [
        detect_args(room, tmp_path / "missing", tmp_path / "a"),
        [*detect_args(room, videos, tmp_path / "c")[:2], "--sequence", str(not_a_sequence),
         *detect_args(room, videos, tmp_path / "c")[4:]],
    ]
    for case in cases:
        python, native = run_python(*case), run_native(*case)
        assert python.returncode == 2 and native.returncode == 2, (case, python.stderr, native.stderr)
        assert error_line(native) == error_line(python)


def test_native_detect_takes_detector_options_and_exposures(room: Path, tmp_path: Path) -> None:
    videos = room / "room" / "videos"
    camera = sorted(videos.iterdir())[0].stem
    extra = ["--no-use-roi", "--no-refine-undistorted", "--detector-option", "corner_refinement=subpix",
             "--detector-option", "adaptive_thresh_constant=9", "--exposure", f"{camera}=0.01"]
    python = run_python(*detect_args(room, videos, tmp_path / "python"), *extra)
    assert python.returncode == 0, python.stderr
    native = run_native(*detect_args(room, videos, tmp_path / "native"), *extra)
    assert native.returncode == 0, native.stderr
    assert (tmp_path / "native" / "tracks.json").read_text() == (tmp_path / "python" / "tracks.json").read_text()
    # The options reached the detector: other corners than the defaults give.
    default = run_native(*detect_args(room, videos, tmp_path / "default"), "--no-use-roi")
    assert default.returncode == 0, default.stderr
    assert (tmp_path / "default" / "tracks.json").read_text() != (tmp_path / "native" / "tracks.json").read_text()


def test_native_detect_bad_detector_options_and_exposures(room: Path, tmp_path: Path) -> None:
    videos = room / "room" / "videos"
    camera = sorted(videos.iterdir())[0].stem
    cases = [
        ["--detector-option", "no_such_knob=1"],
        ["--detector-option", "novalue"],
        ["--detector-option", "corner_refinement=magic"],
        ["--detector-option", "adaptive_thresh_win_size_min=1"],
        ["--exposure", "nocamera=0.01"],
        ["--exposure", f"{camera}=-1"],
    ]
    for case in cases:
        args = [*detect_args(room, videos, tmp_path / "out"), *case]
        python, native = run_python(*args), run_native(*args)
        assert python.returncode == 2 and native.returncode == 2, (case, python.stderr, native.stderr)
        assert error_line(native) == error_line(python), case


@pytest.mark.parametrize(("flag", "value"), [("--floor-relief", "5"), ("--min-pnp-points", "2"),
                                             ("--error-correlation", "-0.1"), ("--ransac-confidence", "1.5")])
def test_both_calibrate_commands_refuse_a_registration_value_alike(tmp_path: Path, flag: str, value: str) -> None:
    """Checked by the core's one check before any input is read: the same line from both."""
    native = run_native("calibrate", "--tracks", "none.json", "--intrinsics", "none", "--out", str(tmp_path / "a"),
                        flag, value)
    python = run_python("calibrate", "--tracks", "none.json", "--intrinsics", "none", "--out", str(tmp_path / "b"),
                        flag, value)
    assert native.returncode == python.returncode == 2
    assert error_line(native) == error_line(python)
    assert flag.lstrip("-").replace("-", "_") in error_line(native)


def test_native_calibrate_takes_every_registration_option() -> None:
    help_text = run_native("calibrate", "--help").stdout
    for field in dataclasses.fields(RegistrationOptions):
        assert "--" + field.name.replace("_", "-") in help_text, field.name


def test_native_detect_takes_every_ingest_option() -> None:
    help_text = run_native("detect", "--help").stdout
    for field in dataclasses.fields(IngestOptions):
        assert "--" + field.name.replace("_", "-") in help_text, field.name


def test_both_check_commands_take_the_same_options() -> None:
    """calibproj check and calibproj-native check take the same options, but those of
    the Python command's own ingest of videos, progress bars and report (README)."""
    def options(help_text: str) -> set[str]:
        return set(re.findall(r"--[a-z][a-z0-9-]*", help_text))

    python, native = options(run_python("check", "--help").stdout), options(run_native("check", "--help").stdout)
    assert python - native == {"--sequence", "--workers", "--no-progress", "--no-report", "--verbose"}
    assert native - python == set()


# What only the Python calibrate has (README, "OR PCs"): the report.
PYTHON_ONLY_CALIBRATE = {"--no-report"}


# What only the Python capture has (README, "Running a room"): the report, as for
# calibrate.
PYTHON_ONLY_CAPTURE = {"--no-report"}


@pytest.mark.parametrize("command, python_only", [
    ("detect", set()),
    ("calibrate", PYTHON_ONLY_CALIBRATE),
    ("capture", PYTHON_ONLY_CAPTURE)])
def test_both_tools_take_the_same_options_but_those_listed(command: str, python_only: set[str]) -> None:
    """The gap between the two command lines is the listed one, no wider: an option added
    to one tool only fails here until it is added to the other or listed (README)."""
    def options(help_text: str) -> set[str]:
        # The options' own lines, not the examples of the description.
        # --verbose: the program's own option, which the Python command takes after it too.
        # An option's line is indented by two spaces; a wrapped help line by more.
        return set(re.findall(r"^  (?:-\w, )?(--[a-z][a-z0-9-]*)", help_text, re.MULTILINE)) - {"--help", "--verbose"}

    python, native = options(run_python(command, "--help").stdout), options(run_native(command, "--help").stdout)
    assert python - native == python_only
    assert native - python == set()


def test_both_tools_describe_a_shared_flag_in_the_core_s_words() -> None:
    """Every flag of the core's table is made from it in both tools: the same metavar and
    help (the Python command may add a note of its own after it)."""
    import argparse

    from calibproj import _core
    from calibproj.cli.main import build_parser

    commands = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices
    native_help = {}
    for flag in _core.formats.command_flags():
        action = next(a for a in commands[flag.command]._actions if flag.name in a.option_strings)
        assert action.help.startswith(flag.help), (flag.command, flag.name)
        assert (action.metavar or "") == flag.metavar, (flag.command, flag.name)
        if flag.command not in native_help:
            native_help[flag.command] = " ".join(run_native(flag.command, "--help").stdout.split())
        assert " ".join(flag.help.split()) in native_help[flag.command], (flag.command, flag.name)


def test_detect_runs_into_one_folder_keep_a_report_each(tmp_path: Path) -> None:
    from fuzz_inputs import dumps, make_inputs

    inputs = make_inputs(tmp_path / "inputs", seed=3)
    (tmp_path / "sequence.json").write_bytes(dumps(inputs.sequence))
    intrinsics = tmp_path / "intrinsics"
    intrinsics.mkdir()
    for name in ("cam0", "cam1"):
        (intrinsics / f"{name}.json").write_bytes(dumps(inputs.detect_intrinsics))
    out = tmp_path / "out"
    for run, name in ((run_python, "first"), (run_native, "second"), (run_python, "tracks")):
        # The noise videos hold no light code: every camera fails (status 1), all is written.
        result = run("detect", str(inputs.videos), "--sequence", str(tmp_path / "sequence.json"),
                     "--intrinsics", str(intrinsics), "--out", str(out / f"{name}.json"), "--no-progress")
        assert result.returncode == 1, result.stderr
    assert sorted(p.name for p in out.iterdir()) == [
        "detect_report.json", "first.detect_report.json", "first.json", "second.detect_report.json", "second.json",
        "tracks.json"]
    for report in out.glob("*detect_report.json"):
        assert json.loads(report.read_text())["schema"] == "calibproj.detect_report/1"
