"""calibproj capture on the virtual operating room: the projection played on the
room's display, four cameras (one zoomed) filming it live over loopback UDP, calibrated
against the room's truth; a camera that never answers, a projector display that does
not exist, malformed site files and SIGTERM each give one line, and the recordings are
never lost."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from calibproj.capture.session import capture
from calibproj.cli.main import main
from calibproj.evaluation.comparison import compare, rotation_angle_deg
from calibproj.cli.demo_room import LIVE_SCENE, LIVE_SEQUENCE
from calibproj.sequence import generate
from calibproj.simulate.scene import CameraChange
from calibproj.simulate.virtual_room import VirtualRoom

from test_live_source import free_udp_port  # the tests folder is on sys.path under pytest
from test_native import NATIVE, run_native

# Measured on the rendered files of the same room and projection (tools/bench/capture.py):
# rotation RMSE 0.02-0.04 deg, centre 0.02-0.03 % of the camera distance.
MAX_ROTATION_RMSE_DEG = 0.15
MAX_CENTRE_RMSE_PCT = 0.15

pytestmark = pytest.mark.skipif(shutil.which("Xvfb") is None, reason="the virtual room needs Xvfb")


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    """The live room running for the module's tests, with its projection."""
    base = tmp_path_factory.mktemp("capture")
    generate(base / "sequence", **LIVE_SEQUENCE)
    with VirtualRoom(LIVE_SCENE, base / "room") as live:
        yield base, live


def site_file(room, name: str, **changes) -> Path:
    """The room's site file, with entries changed or cameras added."""
    base, live = room
    path = live.write_site(base / f"{name}.json", base / "sequence" / "sequence.json",
                           base / "sequence" / "projection.mp4", timeouts={"ready_s": 15, "end_s": 8})
    document = json.loads(path.read_text())
    for key, value in changes.items():
        if key == "cameras":
            document["cameras"].update(value)
        else:
            document[key] = {**document.get(key, {}), **value} if isinstance(value, dict) else value
    path.write_text(json.dumps(document))
    return path


def verdict_lines(cameras: dict, results: Path, live: VirtualRoom) -> str:
    """Each camera's verdict with its reason, then what it recorded and what the room
    sent it, a line each: a failure shows them whole."""
    lines = [f"{name}: {verdict['status']}: {verdict.get('reason')}" for name, verdict in cameras.items()]
    log = results / "recordings" / "capture.json"
    if log.is_file():
        document = json.loads(log.read_text())
        lines += [f"{name}: recorded {camera['frames']} frames from {camera['first_frame_s']} s (the room sent "
                  f"{live.sent.get(name)}, {live.late.get(name, 0)} left out as late), error {camera['error']}"
                  for name, camera in document["cameras"].items()]
        projection = document["projection"]
        lines.append(f"projection: {projection['frames_logged']} frames logged, {projection['dropped_frames']} dropped "
                     f"or late, every camera done {projection['cameras_done_after_end_s']} s after its end")
    return "\n".join(lines)


def recorded_from(results: Path) -> tuple[str, str]:
    """The source and intrinsics provenance.json records: a path, or what was given."""
    inputs = json.loads((results / "provenance.json").read_text())["inputs"]
    entries = (inputs["source"], inputs["intrinsics"])
    return tuple(entry["path"] if isinstance(entry, dict) else entry for entry in entries)


@pytest.fixture(scope="module")
def calibrated(room):
    """The room captured, with a fifth camera in the site file that never answers."""
    base, live = room
    intrinsics = str(base / "room" / "intrinsics" / "far1.json")
    dead = f"udp://127.0.0.1:{free_udp_port()}"
    site = site_file(room, "site", cameras={"dead": {"source": dead, "intrinsics": intrinsics, "open_timeout_s": 2}})
    out = base / "results"
    calibration = capture(site, out, report=False, progress=False)
    assert not live.errors
    return out, dead, calibration


def test_every_camera_is_calibrated_live_and_one_that_never_answers_is_named(room, calibrated):
    base, _ = room
    out, dead, calibration = calibrated
    # The dead camera failed, named with the reason; the others are calibrated.
    assert calibration.failed == {"dead": f"{dead}: cannot open the live source (no answer within 2 s)"}

    comparison = compare(out / "camera_poses.json", base / "room" / "truth.json")
    assert comparison.registered == ["far1", "far4", "near1", "ceiling"] and not comparison.missing
    assert comparison.rotation_rmse_deg < MAX_ROTATION_RMSE_DEG
    assert comparison.translation_rmse_pct < MAX_CENTRE_RMSE_PCT

    # Where the results came from: the site file, its cameras' intrinsics files.
    assert recorded_from(out) == ("../site.json", "the site file's intrinsics files")

    # The recordings are in the results, each the whole projection as the camera sent it.
    log = json.loads((out / "recordings" / "capture.json").read_text())
    assert log["schema"] == "calibproj.capture/1"
    assert log["projection"]["cameras_done_after_end_s"] < 10.0
    assert log["projection"]["frames_logged"] > 0.9 * 9.4 * 30
    assert log["cameras"]["dead"]["error"].startswith(dead)
    assert all(log["cameras"][name]["error"] is None for name in ("far1", "far4", "near1", "ceiling"))
    assert not (out / "recordings" / "dead.mkv").exists()
    # Calibrated again from the recordings: the frames decoded live, so the same MSMs and
    # the same poses to within what Matroska's millisecond timestamps change (the frame
    # rate estimated from the stream's 90 kHz clock may miss the declared one by 1e-4,
    # which the file's rounded clock snaps to).
    again = base / "again"
    status = main(["calibrate", str(out / "recordings"), "--sequence", str(base / "sequence" / "sequence.json"),
                   "--intrinsics", str(base / "room" / "intrinsics"), "--out", str(again), "--no-report",
                   "--no-progress"])
    assert status == 0
    live_poses = json.loads((out / "camera_poses.json").read_text())["cameras"]
    recorded_poses = json.loads((again / "camera_poses.json").read_text())["cameras"]
    assert set(recorded_poses) == set(live_poses)
    live_report = json.loads((out / "detect_report.json").read_text())["cameras"]
    recorded_report = json.loads((again / "detect_report.json").read_text())["cameras"]
    for name, pose in live_poses.items():
        assert recorded_report[name]["msms_kept"] == live_report[name]["msms_kept"]
        assert recorded_report[name]["frames"]["decoded"] == live_report[name]["frames"]["decoded"]
        assert rotation_angle_deg(np.array(recorded_poses[name]["R"]), np.array(pose["R"])) < 0.005
        np.testing.assert_allclose(recorded_poses[name]["center"], pose["center"], atol=1e-4)


def test_a_moved_camera_is_found_and_repaired_by_a_live_check(room, calibrated, capsys):
    base, live = room
    stored, _, _ = calibrated
    assert main(["generate", "--check", str(stored), "--out", str(base / "check_sequence")]) == 0
    capsys.readouterr()
    live.change({"far4": CameraChange(pan_deg=0.5)})
    site = site_file(room, "check")
    repaired = base / "repaired"
    status = main(["capture", str(site), "--check", str(stored), "--sequence",
                   str(base / "check_sequence" / "sequence.json"), "--out", str(repaired), "--no-report",
                   "--no-progress", "--json"])
    cameras = json.loads(capsys.readouterr().out)["cameras"]
    verdicts = {name: verdict["status"] for name, verdict in cameras.items()}
    # Exit status 3, "not confirmed": the stored calibration's dead camera is unknown.
    assert status == 3
    assert verdicts == {"far1": "unchanged", "far4": "moved", "near1": "unchanged", "ceiling": "unchanged",
                        "dead": "unknown"}, verdict_lines(cameras, repaired, live)
    comparison = compare(repaired / "camera_poses.json", base / "room" / "truth.json")
    assert comparison.cameras["far4"].rotation_deg < MAX_ROTATION_RMSE_DEG
    assert (repaired / "check.json").is_file()
    assert recorded_from(repaired) == ("../check.json", "../results/intrinsics")
    assert sorted(p.name for p in (repaired / "recordings").iterdir()) == [
        "capture.json", "ceiling.mkv", "far1.mkv", "far4.mkv", "near1.mkv"]


def test_the_native_capture_calibrates_the_room_and_names_the_dead_camera(room):
    """calibproj-native capture, the OR PC's tool, runs the same room through the same
    core session: every live camera registered against the truth, the dead one named,
    the results folder with its recordings and capture log."""
    base, live = room
    intrinsics = str(base / "room" / "intrinsics" / "far1.json")
    dead = f"udp://127.0.0.1:{free_udp_port()}"
    site = site_file(room, "native", cameras={"dead": {"source": dead, "intrinsics": intrinsics,
                                                        "open_timeout_s": 2}})
    out = base / "native_results"
    done = run_native("capture", str(site), "--out", str(out), "--no-progress", "--export", "yaml")
    assert done.returncode == 1, done.stderr  # a camera failed
    assert f"dead: FAILED {dead}: cannot open the live source (no answer within 2 s)" in done.stdout
    comparison = compare(out / "camera_poses.json", base / "room" / "truth.json")
    assert comparison.registered == ["far1", "far4", "near1", "ceiling"], done.stdout + done.stderr
    assert comparison.rotation_rmse_deg < MAX_ROTATION_RMSE_DEG
    assert comparison.translation_rmse_pct < MAX_CENTRE_RMSE_PCT
    assert (out / "calibration_opencv.yaml").is_file() and (out / "detect_report.json").is_file()
    assert recorded_from(out) == ("../native.json", "the site file's intrinsics files")
    log = json.loads((out / "recordings" / "capture.json").read_text())
    assert log["cameras"]["dead"]["frames"] == 0 and log["cameras"]["far4"]["frames"] > 400
    assert log["projection"]["frames_logged"] > 200 and log["projection"]["cameras_done_after_end_s"] < 10
    assert sorted(p.name for p in (out / "recordings").iterdir()) == [
        "capture.json", "ceiling.mkv", "far1.mkv", "far4.mkv", "near1.mkv"]


def test_the_native_capture_checks_and_repairs_a_moved_camera(room):
    """calibproj-native capture --check on the native results with near1 turned 0.5 deg:
    found moved and repaired, as calibproj check does; the recordings in the repaired
    folder."""
    base, live = room
    stored = base / "native_results"
    if not (stored / "camera_poses.json").is_file():
        pytest.skip("needs the native capture's results (the test above)")
    # The check projection is planned for the stored results' sequence, named here.
    assert main(["generate", "--check", str(stored), "--sequence", str(base / "sequence" / "sequence.json"),
                 "--out", str(base / "native_check")]) == 0
    live.change({"near1": CameraChange(pan_deg=0.5)})
    site = site_file(room, "native_check")
    repaired = base / "native_repaired"
    done = run_native("capture", str(site), "--check", str(stored), "--sequence",
                      str(base / "native_check" / "sequence.json"), "--out", str(repaired), "--no-progress")
    # Exit status 3, "not confirmed": the stored calibration's dead camera is unknown.
    assert done.returncode == 3, done.stdout + done.stderr
    cameras = json.loads((repaired / "check.json").read_text())["cameras"]
    verdicts = {name: verdict["status"] for name, verdict in cameras.items()}
    assert verdicts == {"far1": "unchanged", "far4": "unchanged", "near1": "moved", "ceiling": "unchanged",
                        "dead": "unknown"}, verdict_lines(cameras, repaired, live) + "\n" + done.stdout + done.stderr
    comparison = compare(repaired / "camera_poses.json", base / "room" / "truth.json")
    assert comparison.cameras["near1"].rotation_deg < MAX_ROTATION_RMSE_DEG
    assert recorded_from(repaired) == ("../native_check.json", "../native_results/intrinsics")
    assert sorted(p.name for p in (repaired / "recordings").iterdir()) == [
        "capture.json", "ceiling.mkv", "far1.mkv", "far4.mkv", "near1.mkv"]


def test_a_projector_display_that_does_not_exist_keeps_the_recordings(room, capsys):
    base, _ = room
    site = site_file(room, "no_display", projector={"display": ":4243"})
    out = base / "no_display_results"
    recordings = base / "no_display_recordings"
    status = main(["capture", str(site), "--out", str(out), "--recordings", str(recordings), "--no-progress"])
    error = capsys.readouterr().err.strip().splitlines()[-1]
    assert status == 1
    assert error.startswith("calibproj capture: error: projector (display :4243): cannot play ")
    assert f"the recordings are kept in {recordings}" in error
    assert not out.exists()
    assert sorted(p.name for p in recordings.iterdir()) == ["ceiling.mkv", "far1.mkv", "far4.mkv", "near1.mkv"]


@pytest.mark.parametrize("tool", ["calibproj", "calibproj-native"])
def test_sigterm_stops_everything_and_keeps_the_recordings(room, tool):
    base, _ = room
    site = site_file(room, f"sigterm_{tool}")
    out = base / f"sigterm_results_{tool}"
    recordings = base / f"sigterm_recordings_{tool}"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    program = [sys.executable, "-m", "calibproj"] if tool == "calibproj" else [str(NATIVE)]
    process = subprocess.Popen([*program, "capture", str(site), "--out", str(out), "--recordings", str(recordings),
                                "--no-progress"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    deadline = time.monotonic() + 60
    while not any((recordings / f"{name}.mkv").exists() for name in ("far1", "near1")):
        assert time.monotonic() < deadline and process.poll() is None
        time.sleep(0.2)
    time.sleep(5.0)  # into the projection
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=30)
    assert process.returncode == 130, err
    assert err.strip().splitlines()[-1] == f"{tool} capture: interrupted"
    assert f"the recordings are kept in {recordings}" in err
    assert "Traceback" not in err
    assert not out.exists()
    for name in ("far1", "far4", "near1", "ceiling"):
        assert (recordings / f"{name}.mkv").stat().st_size > 0


@pytest.mark.parametrize("document, message", [
    ({"schema": "calibproj.site/1"}, "sequence: missing"),
    ({"schema": "calibproj.site/2", "cameras": {}}, "newer than this calibproj reads"),
    ({"schema": "calibproj.site/1", "sequence": "s.json", "cameras": {}}, "cameras: expected an object of cameras"),
    ({"schema": "calibproj.site/1", "sequence": "s.json", "cameras": {"a": {"source": "x"}}},
     "cameras.a.intrinsics: missing"),
    ({"schema": "calibproj.site/1", "sequence": "s.json",
      "cameras": {"a": {"source": "x", "intrinsics": "a.json", "exposure_s": 3}}}, "cameras.a.exposure_s: must be"),
    ({"schema": "calibproj.site/1", "sequence": "s.json",
      "cameras": {"a": {"source": "x", "intrinsics": "a.json", "sorce": 1}}}, "cameras.a.sorce: unknown entry"),
    ({"schema": "calibproj.site/1", "sequence": "s.json", "projector": {"screen": 99},
      "cameras": {"a": {"source": "x", "intrinsics": "a.json"}}}, "projector.screen"),
    ({"schema": "calibproj.site/1", "sequence": "s.json", "timeouts": {"ready_s": -1},
      "cameras": {"a": {"source": "x", "intrinsics": "a.json"}}}, "timeouts.ready_s: must be in (0, 3600]"),
])
def test_a_bad_site_file_is_one_line_and_records_nothing(tmp_path, capsys, document, message):
    site = tmp_path / "site.json"
    site.write_text(json.dumps(document))
    status = main(["capture", str(site), "--out", str(tmp_path / "results"), "--no-progress"])
    lines = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(lines) == 1
    assert lines[0].startswith(f"calibproj capture: error: {site}: ") and message in lines[0]
    native = run_native("capture", str(site), "--out", str(tmp_path / "results"), "--no-progress")
    assert native.returncode == 2 and native.stderr.strip() == lines[0].replace("calibproj", "calibproj-native", 1)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["site.json"]


def test_fuzzed_site_files_give_one_line(tmp_path, capsys):
    """Random damage to a valid site file: values of the wrong type, entries removed,
    bytes cut: every run ends with one line and exit status 2, nothing recorded."""
    valid = {"schema": "calibproj.site/1", "sequence": "missing/sequence.json",
             "projector": {"display": ":4244", "screen": 0, "video_output": "x11"},
             "cameras": {"a": {"source": "udp://127.0.0.1:9", "intrinsics": "a.json", "format": "mpegts",
                               "options": {"fifo_size": 100}, "exposure_s": 0.01, "open_timeout_s": 1}},
             "timeouts": {"ready_s": 1, "end_s": 1}}
    rng = np.random.default_rng(4)
    odd_values = [None, True, -1, 0, 1e308, float("nan"), "", "x" * 5000, [], {}, [1, 2], {"a": 1}]
    paths = [("sequence",), ("projector",), ("projector", "display"), ("projector", "screen"), ("cameras",),
             ("cameras", "a"), ("cameras", "a", "source"), ("cameras", "a", "options"),
             ("cameras", "a", "exposure_s"), ("timeouts", "end_s"), ("schema",)]
    for trial in range(60):
        document = json.loads(json.dumps(valid))
        path = paths[rng.integers(len(paths))]
        owner = document
        for key in path[:-1]:
            owner = owner[key]
        if rng.random() < 0.3:
            owner.pop(path[-1], None)
        else:
            owner[path[-1]] = odd_values[rng.integers(len(odd_values))]
        text = json.dumps(document)
        if rng.random() < 0.2:
            text = text[: rng.integers(1, len(text))]
        site = tmp_path / f"site{trial}.json"
        site.write_text(text)
        status = main(["capture", str(site), "--out", str(tmp_path / "results"), "--no-progress"])
        lines = capsys.readouterr().err.strip().splitlines()
        assert status == 2 and len(lines) == 1 and lines[0].startswith("calibproj capture: error: "), (text, lines)
        native = run_native("capture", str(site), "--out", str(tmp_path / "results"), "--no-progress")
        assert native.returncode == 2 and native.stderr.count("\n") == 1, (text, native.stderr)
        assert native.stderr.startswith("calibproj-native capture: error: "), (text, native.stderr)
    assert not any(p.is_dir() for p in tmp_path.iterdir())
