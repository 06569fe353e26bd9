"""The whole pipeline as a user meets it: rendered videos in, a results folder out."""

from __future__ import annotations

import json
import logging
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibproj.cli.main import EXIT_FAILURE, EXIT_USAGE, main
from calibproj.evaluation.comparison import compare
from calibproj.evaluation.independent import evaluate
from calibproj.sequence import generate
from calibproj.pipeline import calibrate
from calibproj.registration.driver import RegistrationOptions
from calibproj.simulate.geometric import simulate_tracks
from calibproj.simulate.render import simulate_videos

# The small room: 3 cameras at 640x360 (fx 305) 3.5 m from the floor centre; its poses
# are known less well than the paper rig's, hence looser bounds than the registration's.
MAX_ROTATION_RMSE_DEG = 0.3
MAX_TRANSLATION_RMSE_PCT = 0.2


@pytest.fixture(scope="module", params=["aruco:4X4_50", "apriltag:tag36h11"])
def room(request, tmp_path_factory) -> Path:
    """A short sequence of the given markers, rendered in the small room."""
    out = tmp_path_factory.mktemp(request.param.replace(":", "_"))
    sequence = generate(out / "sequence", markers=request.param, arrays=12, scales=(3.0, 5.0, 8.0), video=False)
    simulate_videos("small", sequence, out / "room", seed=1)
    return out


def calibrate_room(room: Path, results: Path, **options):
    return calibrate(room / "room" / "videos", room / "room" / "intrinsics",
                     sequence=room / "sequence" / "sequence.json", out=results, progress=False, **options)


def test_videos_to_results_in_both_models(room: Path, tmp_path: Path) -> None:
    results = tmp_path / "results"
    calibration = calibrate_room(room, results, exports=["yaml", "colmap", "anipose"])
    assert calibration.failed == {}
    for name in ("camera_poses.json", "metrics.json", "points.ply", "tracks.json", "detect_report.json",
                 "report.html", "calibration_opencv.yaml", "calibration.toml", "colmap/images.txt"):
        assert (results / name).is_file(), name
    assert (results / "intrinsics").is_dir()
    truth = room / "room" / "truth.json"
    errors = compare(results / "camera_poses.json", truth)
    assert errors.missing == []
    assert errors.rotation_rmse_deg < MAX_ROTATION_RMSE_DEG
    assert errors.translation_rmse_pct < MAX_TRANSLATION_RMSE_PCT
    assert all(m.mean_px < 0.5 for m in calibration.metrics.values())
    # The paper's evaluation on the rendering's independent points (0.1 px noise).
    evaluation = evaluate(results, room / "room" / "eval_tracks.json")
    assert evaluation.to_json()["success_rate"]["0.5"] == pytest.approx(100.0)
    # The FREE model from the tracks the videos gave.
    free = calibrate(results / "tracks.json", results / "intrinsics", out=tmp_path / "free",
                     options=RegistrationOptions(model="free"), report=False)
    assert free.failed == {}
    errors = compare(tmp_path / "free" / "camera_poses.json", truth)
    assert errors.rotation_rmse_deg < MAX_ROTATION_RMSE_DEG
    assert errors.translation_rmse_pct < MAX_TRANSLATION_RMSE_PCT
    # The report page embeds its plots, a frame of each camera among them.
    page = (results / "report.html").read_text()
    assert page.count("<img") >= 4 and all(name in page for name in calibration.registered)
    assert "keep a fixed phase to the projector's" in page  # why one offset is known better than another
    detect_report = json.loads((results / "detect_report.json").read_text())
    for name in calibration.registered:
        thumbnail = detect_report["cameras"][name]["thumbnail"]
        frame = cv2.imread(str(results / thumbnail["file"]), cv2.IMREAD_GRAYSCALE)
        assert frame is not None and frame.shape[1] == round(640 * thumbnail["scale"])
        assert f"{name}: a frame with its detections" in page
        # Videos that are not beside the results folder are recorded by their absolute path.
        assert detect_report["cameras"][name]["video"] == str((room / "room" / "videos" / f"{name}.mp4").resolve())
    provenance = json.loads((results / "provenance.json").read_text())
    assert set(provenance["inputs"]["videos"]) == set(calibration.registered)
    assert provenance["markers"] == detect_report["markers"] and provenance["command"] is None
    assert cv2.FileStorage(str(results / "calibration_opencv.yaml"), cv2.FILE_STORAGE_READ).isOpened()


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "calibproj", *args], capture_output=True, text=True)


def one_error_line(result: subprocess.CompletedProcess) -> str:
    lines = [line for line in result.stderr.splitlines() if line.startswith("calibproj calibrate:")]
    assert len(lines) == 1, result.stderr
    return lines[0]


@pytest.mark.parametrize("room", ["aruco:4X4_50"], indirect=True)
def test_a_terminated_run_stops_as_an_interrupted_one(room: Path, tmp_path: Path) -> None:
    """SIGTERM (``kill``, a service manager stopping a job) while the videos are read: the
    run stops as on Ctrl-C, with status 130 and one line, and leaves no results folder
    and no staging folder behind."""
    import signal
    import time

    out = tmp_path / "results"
    process = subprocess.Popen([sys.executable, "-m", "calibproj", "calibrate", str(room / "room" / "videos"),
                                "--sequence", str(room / "sequence" / "sequence.json"),
                                "--intrinsics", str(room / "room" / "intrinsics"), "--out", str(out),
                                "--no-progress"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60.0
        while not list(tmp_path.glob(".results.tmp-*")):  # opened before the ingest starts
            assert process.poll() is None and time.monotonic() < deadline
            time.sleep(0.01)
        process.send_signal(signal.SIGTERM)
        _, stderr = process.communicate(timeout=60.0)
    finally:
        process.kill()
    assert process.returncode == 130, stderr
    assert stderr.splitlines()[-1] == "calibproj calibrate: interrupted"
    assert not out.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("room", ["aruco:4X4_50"], indirect=True)
def test_bad_invocations_exit_non_zero_with_one_clear_line(room: Path, tmp_path: Path) -> None:
    videos, intrinsics = room / "room" / "videos", room / "room" / "intrinsics"
    sequence = room / "sequence" / "sequence.json"
    missing = run_cli("calibrate", str(tmp_path / "nowhere"), "--sequence", str(sequence),
                      "--intrinsics", str(intrinsics), "--out", str(tmp_path / "a"))
    assert missing.returncode == 2 and "nowhere" in one_error_line(missing)

    (tmp_path / "empty").mkdir()
    no_videos = run_cli("calibrate", str(tmp_path / "empty"), "--sequence", str(sequence),
                        "--intrinsics", str(intrinsics), "--out", str(tmp_path / "b"))
    assert no_videos.returncode == 2 and "empty" in one_error_line(no_videos)

    other = run_cli("calibrate", str(videos), "--sequence", str(room / "room" / "truth.json"),
                    "--intrinsics", str(intrinsics), "--out", str(tmp_path / "c"))
    assert other.returncode == 2 and "truth.json" in one_error_line(other)

    no_sequence = run_cli("calibrate", str(videos), "--intrinsics", str(intrinsics), "--out", str(tmp_path / "d"))
    assert no_sequence.returncode == 2 and "--sequence" in one_error_line(no_sequence)

    # Intrinsics missing for one camera: that camera is reported, the others calibrated.
    partial = tmp_path / "partial"
    shutil.copytree(intrinsics, partial)
    (partial / "cam2.json").unlink()
    result = run_cli("calibrate", str(videos), "--sequence", str(sequence), "--intrinsics", str(partial),
                     "--out", str(tmp_path / "e"), "--no-report", "--no-progress")
    assert result.returncode == 1
    assert one_error_line(result).endswith("1 camera(s) failed: cam2 (why: in the table above)")
    assert f"cam2          FAILED     {partial / 'cam2.json'}: no intrinsics file for camera 'cam2'" in result.stdout
    poses = json.loads((tmp_path / "e" / "camera_poses.json").read_text())
    assert sorted(poses["cameras"]) == ["cam1", "cam3"] and "cam2" in poses["failed"]

    # A broken intrinsics file (true in K, once read as 1.0) fails its own camera only.
    broken = tmp_path / "broken"
    shutil.copytree(intrinsics, broken)
    document = json.loads((broken / "cam3.json").read_text())
    document["K"][1][1] = True
    (broken / "cam3.json").write_text(json.dumps(document))
    result = run_cli("calibrate", str(videos), "--sequence", str(sequence), "--intrinsics", str(broken),
                     "--out", str(tmp_path / "f"), "--no-report", "--no-progress")
    assert result.returncode == 1
    reason = f"{broken / 'cam3.json'}: K: expected numbers, got true"
    assert one_error_line(result).endswith("failed: cam3 (why: in the table above)")
    assert f"cam3          FAILED     {reason}" in result.stdout
    poses = json.loads((tmp_path / "f" / "camera_poses.json").read_text())
    assert sorted(poses["cameras"]) == ["cam1", "cam2"] and poses["failed"] == {"cam3": reason}


def test_a_camera_whose_intrinsics_file_is_bad_or_missing_fails_alone(
        tmp_path: Path, capsys: pytest.CaptureFixture, caplog: pytest.LogCaptureFixture) -> None:
    """From tracks: one camera's intrinsics file holds true in K, another's is missing.
    Those two fail, with the file and the problem in the results, the log and the
    summary table, and the error line names them; the seven others are calibrated as well as ever (exit status 1)."""
    simulate_tracks("or-full", tmp_path / "sim", noise_px=0.3, seed=1, eval_points=0, eval_points_per_camera=0)
    intrinsics = tmp_path / "sim" / "intrinsics"
    document = json.loads((intrinsics / "far2.json").read_text())
    document["K"][0][0] = True
    (intrinsics / "far2.json").write_text(json.dumps(document))
    (intrinsics / "near2.json").unlink()
    results = tmp_path / "results"
    caplog.set_level(logging.INFO)
    status = main(["calibrate", "--tracks", str(tmp_path / "sim" / "tracks.json"), "--intrinsics", str(intrinsics),
                   "--out", str(results), "--no-report", "--no-progress", "--export", "yaml",
                   "--scale", "camera-height:far1=2.5"])
    assert status == EXIT_FAILURE
    reasons = {"far2": f"{intrinsics / 'far2.json'}: K: expected numbers, got true",
               "near2": f"{intrinsics / 'near2.json'}: no intrinsics file for camera 'near2' (also looked for "
                        "near2.yaml, near2.yml, near2.xml)"}
    printed = capsys.readouterr()
    assert ": error: " not in printed.err
    assert "calibproj calibrate: 2 camera(s) failed: far2, near2 (why: in the table above)" in printed.err
    assert all(f"{name:<14}FAILED     {reason}" in printed.out for name, reason in reasons.items())
    # The summary is printed last: each camera's status, sigmas in the report's units.
    summary = printed.out.splitlines()
    assert summary[-1] == f"results: {results} (in metres)"
    assert summary[-2].startswith("expected 3D error (1 sigma): ") and summary[-2].endswith("over the working volume")
    assert summary[-3] == "sigmas: 1 sigma, relative to the reference camera; centre sigmas in mm"
    statuses = {line.split()[0]: line.split()[1] for line in summary if line.split()[:1] in (["far3"], ["near1"])}
    assert statuses == {"far3": "reference", "near1": "ok"}  # far3: the initial pair's first
    # Messages name the files where they are once the run has ended.
    assert f"exported yaml: {results / 'calibration_opencv.yaml'}" in caplog.text and ".tmp-" not in caplog.text
    assert all(f"camera {name} failed: {reason}" in caplog.text for name, reason in reasons.items())
    assert json.loads((results / "camera_poses.json").read_text())["failed"] == reasons
    metrics = json.loads((results / "metrics.json").read_text())["cameras"]
    assert {name: metrics[name]["failure"] for name in reasons} == reasons
    errors = compare(results / "camera_poses.json", tmp_path / "sim" / "truth.json")
    assert sorted(errors.missing) == ["far2", "near2"] and len(errors.registered) == 7
    assert errors.rotation_rmse_deg < MAX_ROTATION_RMSE_DEG
    assert errors.translation_rmse_pct < MAX_TRANSLATION_RMSE_PCT


def test_exposures_with_tracks_are_refused_before_anything_is_written(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="exposures apply to videos, not to tracks"):
        calibrate(tmp_path / "tracks.json", tmp_path, out=tmp_path / "results", exposures={"cam1": 0.01})
    assert not (tmp_path / "results").exists()


def test_a_known_exposure_reaches_the_sync(room: Path, tmp_path: Path) -> None:
    """calibrate(exposures=...) fits cam2's light codes with its exposure as given."""
    timing = json.loads((room / "room" / "truth.json").read_text())["timing"]["cameras"]["cam2"]
    calibration = calibrate_room(room, tmp_path / "results", report=False, exposures={"cam2": timing["exposure_s"]})
    assert calibration.failed == {}
    sync = json.loads((tmp_path / "results" / "detect_report.json").read_text())["cameras"]["cam2"]["sync"]
    assert sync["exposure_frames"] == pytest.approx(timing["exposure_s"] * timing["fps"], rel=1e-6)


def test_videos_without_intrinsics_files(room: Path, tmp_path: Path) -> None:
    """Cameras without an intrinsics file start from a guessed field of view (100 deg;
    the truth is 93). With one camera calibrated, the floor's metric is known and the
    two others' focal lengths follow; with none, three cameras do not determine three
    focal lengths (planar self-calibration needs four), and all are held and reported."""
    from calibproj.formats.intrinsics import load_intrinsics_dir, read_intrinsics

    one_file = tmp_path / "intrinsics"
    one_file.mkdir()
    shutil.copy(room / "room" / "intrinsics" / "cam1.json", one_file)
    guessed = 320.0 / np.tan(np.radians(50.0))
    for source, results in [(one_file, tmp_path / "one"), (None, tmp_path / "none")]:
        calibration = calibrate(room / "room" / "videos", source, sequence=room / "sequence" / "sequence.json",
                                out=results, progress=False, report=False, nominal_fov_deg=100.0,
                                refine_intrinsics=["focal,k1", "cam1=none"] if source else "focal,k1")
        assert calibration.failed == {}
        document = json.loads((results / "self_calibration.json").read_text())
        refined = load_intrinsics_dir(results / "intrinsics")
        for name in ("cam2", "cam3"):
            camera = document["cameras"][name]
            truth = read_intrinsics(room / "room" / "intrinsics" / f"{name}.json")
            assert camera["given"]["focal"] == pytest.approx(guessed)
            if source is not None:
                assert camera["refined"] == ["focal", "k1"], name
                assert abs(refined[name].K[0, 0] / truth.K[0, 0] - 1.0) < 0.01, name
            else:
                assert camera["refined"] == [] and "not determined" in camera["held"]["focal"], name
                assert refined[name].K[0, 0] == pytest.approx(guessed)


@pytest.mark.parametrize("arguments, message", [
    (["--nominal-fov", "100"], "--nominal-fov needs --refine-intrinsics"),
    (["--nominal-fov", "200", "--refine-intrinsics", "focal"], "must be a horizontal field of view in [10, 170]"),
    ([], "no intrinsics: give --intrinsics DIR"),
])
def test_nominal_field_of_view_misuse_is_one_line(room: Path, tmp_path: Path, capsys, arguments, message) -> None:
    code = main(["calibrate", str(room / "room" / "videos"), "--sequence", str(room / "sequence" / "sequence.json"),
                 "--out", str(tmp_path / "out"), *arguments])
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_nominal_field_of_view_needs_videos(room: Path, tmp_path: Path, capsys) -> None:
    tracks = simulate_tracks("small", tmp_path / "sim", seed=0).tracks
    tracks.write(tmp_path / "tracks.json")
    code = main(["calibrate", "--tracks", str(tmp_path / "tracks.json"), "--out", str(tmp_path / "out"),
                 "--nominal-fov", "90", "--refine-intrinsics", "focal"])
    assert code == 2 and "--nominal-fov needs videos" in capsys.readouterr().err


def refused_before_the_ingest(capsys: pytest.CaptureFixture, out: Path, *args: str) -> str:
    """Run ``calibrate ARGS --out OUT``: status 2, one line, no output folder started."""
    status = main(["calibrate", *args, "--out", str(out), "--no-progress"])
    printed = capsys.readouterr()
    lines = printed.err.strip().splitlines()
    assert status == EXIT_USAGE and len(lines) == 1, printed.err
    assert "MSMs" not in printed.err and not out.exists() and not list(out.parent.glob(f".{out.name}.*"))
    return lines[0]


def linked(folder: Path, videos: dict[str, Path]) -> Path:
    folder.mkdir()
    for name, source in videos.items():
        (folder / name).symlink_to(source)
    return folder


@pytest.mark.parametrize("room", ["aruco:4X4_50"], indirect=True)
def test_mistakes_seen_before_the_ingest_stop_it_in_one_line_naming_both_sides(
        room: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """Too few cameras, videos and intrinsics named apart, a video renamed by its camera,
    the projector's own video among the cameras (whatever its name), a video given as
    the sequence or as tracks: each is one line before any video is decoded, naming
    what is on both sides and what was likely meant."""
    from calibproj.sequence.builder import write_sequence
    from calibproj.sequence.sequence import Sequence

    videos, intrinsics = room / "room" / "videos", room / "room" / "intrinsics"
    sequence = room / "sequence" / "sequence.json"
    out = tmp_path / "results"
    common = ["--sequence", str(sequence), "--intrinsics", str(intrinsics)]

    one = linked(tmp_path / "one", {"cam1.mp4": videos / "cam1.mp4"})
    line = refused_before_the_ingest(capsys, out, str(one), *common)
    assert line.endswith(f"{one}: one camera video (cam1.mp4); a calibration needs two or more cameras that see "
                         "the projection together")

    named_apart = tmp_path / "named_apart"
    named_apart.mkdir()
    for k in (1, 2, 3):
        shutil.copy(intrinsics / f"cam{k}.json", named_apart / f"c{k}.json")
    line = refused_before_the_ingest(capsys, out, str(videos), "--sequence", str(sequence),
                                     "--intrinsics", str(named_apart))
    assert (f"cam1.mp4, cam2.mp4, cam3.mp4 in {videos} have no intrinsics in {named_apart}, whose c1.json, "
            "c2.json, c3.json match no video" in line)
    assert line.endswith("(rename c1.json to cam1.json, c2.json to cam2.json, c3.json to cam3.json?)")

    renamed = linked(tmp_path / "renamed", {"GOPR0042.MP4": videos / "cam1.mp4", "cam2.mp4": videos / "cam2.mp4",
                                            "cam3.mp4": videos / "cam3.mp4"})
    line = refused_before_the_ingest(capsys, out, str(renamed), *common)
    assert (f"GOPR0042.MP4 in {renamed} has no intrinsics in {intrinsics}, whose cam1.json matches no video"
            in line and line.endswith("(rename GOPR0042.MP4 to cam1.MP4?)"))

    write_sequence(tmp_path / "projection", Sequence.load(sequence), preset="ultrafast")
    projector = linked(tmp_path / "with_projector", {
        "cam1.mp4": videos / "cam1.mp4", "cam2.mp4": videos / "cam2.mp4", "cam3.mp4": videos / "cam3.mp4",
        "cam4.mp4": tmp_path / "projection" / "projection.mp4"})
    line = refused_before_the_ingest(capsys, out, str(projector), *common)
    assert f"{projector / 'cam4.mp4'}: is the projector's video of the sequence, not a camera's recording" in line

    line = refused_before_the_ingest(capsys, out, str(videos), "--sequence", str(videos / "cam1.mp4"),
                                     "--intrinsics", str(intrinsics))
    assert line.endswith(f"{videos / 'cam1.mp4'}: is a video (MP4/MOV), not a calibproj sequence file; give the "
                         "sequence.json that calibproj generate wrote with it")
    line = refused_before_the_ingest(capsys, out, str(videos), "--sequence",
                                     str(tmp_path / "projection" / "projection.mp4"), "--intrinsics", str(intrinsics))
    assert line.endswith(f"the sequence file beside it is {tmp_path / 'projection' / 'sequence.json'}")
    line = refused_before_the_ingest(capsys, out, str(sequence), *common)
    assert line.endswith("; a sequence file is given with --sequence, the camera videos as their folder")
    line = refused_before_the_ingest(capsys, out, str(videos / "cam2.mp4"), *common)
    assert line.endswith(f"{videos / 'cam2.mp4'}: is a video (MP4/MOV), not a calibproj tracks file; camera videos "
                         f"are given as their folder ({videos})")
