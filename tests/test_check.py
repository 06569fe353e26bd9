"""The camera check against truth: a simulated camera kept, moved, re-zoomed or nudged
below the tolerance, tested on new noisy observations of the stored points."""

from __future__ import annotations

import json
import math
import subprocess

import cv2
import numpy as np
import pytest

from calibproj import _core

WIDTH, HEIGHT = 1280, 720


def look_at(centre: np.ndarray, target: np.ndarray) -> np.ndarray:
    """cam_from_world rotation of a camera at ``centre`` looking at ``target`` (x right, y down)."""
    forward = (target - centre) / np.linalg.norm(target - centre)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return np.stack([right, down, forward])


def rotation(axis, degrees: float) -> np.ndarray:
    import cv2

    vector = np.asarray(axis, float) / np.linalg.norm(axis) * math.radians(degrees)
    return cv2.Rodrigues(vector)[0]


def project(K, R, t, points):
    camera = points @ R.T + t
    pixels = camera @ K.T
    return pixels[:, :2] / pixels[:, 2:]


def floor_camera(focal: float, floor_x: np.ndarray, floor_y: np.ndarray) -> dict:
    """A camera 2.8 m up, looking at the floor 2.5 m away, the floor points (a grid over
    floor_x x floor_y) it sees, and a working volume above them."""
    K = np.array([[focal, 0, 640], [0, focal, 360], [0, 0, 1]])
    centre = np.array([0.0, -2.5, 2.8])
    R = look_at(centre, np.array([0.0, 0.0, 0.0]))
    t = -R @ centre
    xs, ys = np.meshgrid(floor_x, floor_y)
    floor = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    inside = project(K, R, t, floor)
    assert np.all((inside >= 0) & (inside <= [WIDTH, HEIGHT]))
    volume = np.concatenate([floor + [0, 0, h] for h in (0.0, 0.9, 1.7)])
    return {"K": K, "R": R, "t": t, "points": floor, "volume": volume}


@pytest.fixture
def stored():
    return floor_camera(1100.0, np.linspace(-1.0, 1.0, 9), np.linspace(-0.7, 0.7, 7))


def turned(stored, axis, degrees: float) -> tuple[np.ndarray, np.ndarray]:
    """The stored camera turned about its own centre by ``degrees`` about ``axis`` (its frame)."""
    R = rotation(axis, degrees) @ stored["R"]
    return R, -R @ (-stored["R"].T @ stored["t"])


def check(stored, K, R, t, noise_px=0.1, seed=0, rotation_sigma=1e-4, centre_sigma=1e-3, **options):
    """The stored camera tested on observations made by the camera (K, R, t)."""
    rng = np.random.default_rng(seed)
    observed = project(K, R, t, stored["points"]) + rng.normal(0.0, noise_px, (len(stored["points"]), 2))
    return _core.check.check_camera(stored["K"], stored["R"], stored["t"], rotation_sigma, centre_sigma,
                                    stored["points"], observed, stored["volume"], WIDTH, HEIGHT, **options)


def test_an_unchanged_camera_is_unchanged_over_many_noise_draws(stored) -> None:
    verdicts = [check(stored, stored["K"], stored["R"], stored["t"], seed=seed) for seed in range(40)]
    assert all(v.status == "unchanged" for v in verdicts)
    assert np.mean([v.noise_px for v in verdicts]) == pytest.approx(0.1, rel=0.15)


def test_what_a_check_can_resolve_is_predicted_from_the_points_it_will_see(stored) -> None:
    """The predicted uncertainty of the working volume's shift in the image against
    Monte Carlo fits of pose and focal length (OpenCV's calibration of one planar view,
    aspect and principal point fixed, as the check fits them); the check reports the
    same; points spread over the view resolve far better than a patch of as many."""
    K, R, t, points, volume = (stored[key] for key in ("K", "R", "t", "points", "volume"))
    predicted = _core.check.predicted_shift_sigma(K, R, t, points, volume, WIDTH, HEIGHT, 0.1)
    rng = np.random.default_rng(5)
    flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_PRINCIPAL_POINT | cv2.CALIB_FIX_ASPECT_RATIO
             | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3)
    seen = project(K, R, t, volume)
    inside = np.all((seen >= 0) & (seen <= [WIDTH, HEIGHT]), axis=1)
    shifts = []
    for _ in range(300):
        observed = project(K, R, t, points) + rng.normal(0.0, 0.1, (len(points), 2))
        _, K_fit, _, rvecs, tvecs = cv2.calibrateCamera([points.astype(np.float32)], [observed.astype(np.float32)],
                                                        (WIDTH, HEIGHT), K.copy(), np.zeros(5), flags=flags)
        R_fit = cv2.Rodrigues(rvecs[0])[0]
        shifts.append(project(K_fit, R_fit, tvecs[0].ravel(), volume[inside]) - seen[inside])
    shifts = np.array(shifts)  # (draws, points, 2)
    measured = max(np.sqrt(np.linalg.eigvalsh(np.cov(shifts[:, k].T)).max()) for k in range(shifts.shape[1]))
    assert predicted == pytest.approx(measured, rel=0.15)
    verdict = check(stored, K, R, t, noise_px=0.1, rotation_sigma=1e-9, centre_sigma=1e-9, model_error_px=0.0)
    assert verdict.status == "unchanged"
    assert verdict.volume_shift_sigma_px == pytest.approx(predicted, rel=0.2)
    # As many points in one corner of the view leave the camera free to turn.
    corner = points[(points[:, 0] < -0.2) & (points[:, 1] < 0.0)]
    spread = points[np.linspace(0, len(points) - 1, len(corner)).round().astype(int)]
    assert _core.check.predicted_shift_sigma(K, R, t, corner, volume, WIDTH, HEIGHT, 0.1) > 2.0 * \
        _core.check.predicted_shift_sigma(K, R, t, spread, volume, WIDTH, HEIGHT, 0.1)
    assert math.isinf(_core.check.predicted_shift_sigma(K, R, t, points[:5], volume, WIDTH, HEIGHT, 0.1))


def test_a_moved_camera_is_moved_with_its_new_pose(stored) -> None:
    R = rotation([0.3, 1.0, 0.2], 0.3) @ stored["R"]
    centre = -stored["R"].T @ stored["t"] + [0.01, -0.02, 0.005]
    t = -R @ centre
    verdict = check(stored, stored["K"], R, t)
    assert verdict.status == "moved", verdict.reason
    assert verdict.focal_scale == 1.0
    # The pose found is the true one, to a small share of the change.
    error = np.degrees(np.arccos(np.clip((np.trace(verdict.R @ R.T) - 1) / 2, -1, 1)))
    assert error < 0.02 and verdict.rotation_change_deg == pytest.approx(0.3, abs=0.05)
    assert np.linalg.norm(-verdict.R.T @ verdict.t - centre) < 0.005
    assert verdict.rms_after_px < 0.2 < verdict.rms_before_px
    assert verdict.volume_shift_px > 5.0


def test_a_rezoomed_camera_is_rezoomed_with_its_focal_length(stored) -> None:
    K = stored["K"].copy()
    K[0, 0] *= 1.03
    K[1, 1] *= 1.03
    verdict = check(stored, K, stored["R"], stored["t"])
    assert verdict.status == "rezoomed", verdict.reason
    assert verdict.focal_change == pytest.approx(0.03, abs=0.002)
    assert "re-zoomed" in verdict.reason


def test_a_change_below_the_tolerance_leaves_the_camera_unchanged(stored) -> None:
    R, t = turned(stored, [1.0, 0.0, 0.0], 0.02)
    exact = {"noise_px": 0.02, "rotation_sigma": 1e-6, "centre_sigma": 1e-6}
    verdict = check(stored, stored["K"], R, t, **exact)
    assert verdict.chi2 > verdict.chi2_threshold  # significant, yet
    assert verdict.volume_shift_px < 0.5 and verdict.status == "unchanged"
    assert verdict.reason.startswith("a change within the tolerance")
    # The same change counts with a tolerance below it.
    assert check(stored, stored["K"], R, t, tolerance_px=0.2, **exact).status == "moved"


def test_the_stored_uncertainty_is_not_taken_for_a_move(stored) -> None:
    """A weak stored pose (0.1 deg off, known to 0.1 deg) is not called moved."""
    R, t = turned(stored, [0.0, 1.0, 0.0], 0.1)
    assert check(stored, stored["K"], R, t, rotation_sigma=math.radians(0.1)).status == "unchanged"
    assert check(stored, stored["K"], R, t, rotation_sigma=1e-5).status == "moved"


def test_too_few_points_and_outliers(stored) -> None:
    few = {**stored, "points": stored["points"][:5]}
    verdict = check(few, stored["K"], stored["R"], stored["t"])
    assert verdict.status == "unknown" and "only 5" in verdict.reason
    # Wrong observations (ids decoded wrongly) are left out of the test.
    rng = np.random.default_rng(3)
    observed = project(stored["K"], stored["R"], stored["t"], stored["points"]) + rng.normal(0, 0.1, (63, 2))
    observed[:4] += 40.0
    verdict = _core.check.check_camera(stored["K"], stored["R"], stored["t"], 1e-4, 1e-3, stored["points"], observed,
                                       stored["volume"], WIDTH, HEIGHT)
    assert verdict.status == "unchanged" and verdict.inliers == 59


@pytest.mark.parametrize("case", ["shape", "nan", "option", "value"])
def test_bad_input_is_one_clear_error(stored, case: str) -> None:
    points, observed = stored["points"], project(stored["K"], stored["R"], stored["t"], stored["points"])
    kwargs = {}
    if case == "shape":
        observed = observed[:, :1]
    elif case == "nan":
        observed = observed.copy()
        observed[0, 0] = np.nan
    elif case == "option":
        kwargs = {"tolerance": 1.0}
    else:
        kwargs = {"min_points": 2}
    with pytest.raises(ValueError, match={"shape": "observed", "nan": "finite", "option": "tolerance_px",
                                          "value": "min_points"}[case]):
        _core.check.check_camera(stored["K"], stored["R"], stored["t"], 0.0, 0.0, points, observed,
                                 stored["volume"], WIDTH, HEIGHT, **kwargs)


# -- a stored calibration checked with a second recording of the room ----------------


@pytest.fixture(scope="module")
def room(tmp_path_factory) -> dict:
    """The demo room calibrated (metric), then recorded again with far2 turned by 0.5 deg
    and the ceiling camera zoomed 3 % in: the check's observations of the same arrays."""
    from calibproj.pipeline import calibrate
    from calibproj.sequence import build_sequence
    from calibproj.simulate import simulate_tracks
    from calibproj.simulate.scene import CameraChange, load_scene

    folder = tmp_path_factory.mktemp("check")
    scene = load_scene("demo")
    sequence = build_sequence(arrays=24, scales=(1.0, 3.0, 6.0))
    sequence.save(folder / "sequence.json")
    first = simulate_tracks(scene, folder / "first", noise_px=0.1, seed=5, layout=sequence)
    height = scene.camera("far1").position[2]
    calibrate(first.tracks, first.intrinsics, sequence=folder / "sequence.json", out=folder / "results",
              scale=f"camera-height:far1={height}", report=False)
    changes = {"far2": CameraChange(pan_deg=0.5), "ceiling": CameraChange(zoom=1.03)}
    changed = scene.changed(changes)
    again = simulate_tracks(changed, folder / "again", noise_px=0.1, seed=6, layout=sequence)
    kept = simulate_tracks(scene, folder / "kept", noise_px=0.1, seed=7, layout=sequence)
    return {"folder": folder, "scene": scene, "changed": changed, "again": again, "kept": kept}


def test_a_second_recording_of_an_unchanged_room_confirms_every_camera(room) -> None:
    from calibproj.check.repair import check

    result = check(room["folder"] / "results", room["kept"].tracks)
    assert result.trusted and not result.changed
    assert {verdict.status for verdict in result.cameras.values()} == {"unchanged"}





# An error of the lens model up to 2 px at the image's sides.
LENS_ERROR_PX = 2.0


def with_lens_error(tracks, camera: str, width: float, height: float, amplitude_px: float):
    """``tracks`` with a smooth error in ``camera``'s pixels that its lens model does not
    have (``amplitude_px`` at the left and right edges, growing with the square of the
    distance from the centre line): the same in every recording."""
    xy = tracks.xy.copy()
    rows = tracks.camera_index == tracks.camera_names.index(camera)
    across = (xy[rows, 0] - width / 2.0) / (width / 2.0)
    xy[rows, 1] += amplitude_px * across**2
    return tracks.with_xy(xy)


def test_a_lens_model_error_in_one_part_of_the_image_is_not_taken_for_a_move(room) -> None:
    """A check projection that shows a camera one part of its image: against the fit to
    the other points of its calibration, the lens model's error there turns its fit
    (far5 of rendered rooms: 0.018 deg, "moved" at 0.67 px); against the same points'
    calibration observations, the error is in both and the camera is unchanged."""
    from calibproj.formats.calibration import Calibration
    from calibproj.check.repair import check_cameras
    from calibproj.formats.intrinsics import load_intrinsics_dir
    from calibproj.formats.tracks import Tracks

    results = room["folder"] / "results"
    calibration, intrinsics = Calibration.load(results), load_intrinsics_dir(results / "intrinsics")
    width, height = intrinsics["far1"].resolution
    stored = with_lens_error(Tracks.read(results / "tracks.json"), "far1", width, height, LENS_ERROR_PX)
    kept = with_lens_error(room["kept"].tracks, "far1", width, height, LENS_ERROR_PX)
    far1 = kept.camera_names.index("far1")
    ids, xy = kept.observations("far1")
    corner = ids[xy[:, 0] < np.percentile(xy[:, 0], 40)]
    assert 40 <= len(corner) < 0.5 * len(ids)

    def only(tracks, keep_corner: bool):
        """far1's observations of the corner's points (or of every other point); the
        other cameras' as they are."""
        in_corner = np.isin(tracks.point_ids[tracks.point_index], corner)
        return tracks.select((tracks.camera_index != far1) | (in_corner == keep_corner))

    result = check_cameras(calibration, intrinsics, only(kept, True), stored_tracks=stored)
    assert result.cameras["far1"].status == "unchanged", result.cameras["far1"].reason
    # The same points' reference is what makes the difference: against the other points
    # (the fit to all of them, before), the corner's fit turns.
    elsewhere = check_cameras(calibration, intrinsics, only(kept, True), stored_tracks=only(stored, False))
    assert elsewhere.cameras["far1"].status == "moved", elsewhere.cameras["far1"].reason


def test_the_moved_and_rezoomed_cameras_are_found_and_repaired(room) -> None:
    from calibproj.formats.calibration import Calibration
    from calibproj.check.repair import CHECK_FILE, check
    from calibproj.evaluation.comparison import CameraPoses, compare
    from calibproj.formats.intrinsics import load_intrinsics_dir

    out = room["folder"] / "repaired"
    result = check(room["folder"] / "results", room["again"].tracks, out=out)
    statuses = {name: verdict.status for name, verdict in result.cameras.items()}
    assert statuses == {"far1": "unchanged", "far2": "moved", "far4": "unchanged", "far5": "unchanged",
                        "near1": "unchanged", "ceiling": "rezoomed"}, {n: v.reason for n, v in result.cameras.items()}
    assert result.cameras["far2"].rotation_change_deg == pytest.approx(0.5, abs=0.03)
    assert result.cameras["ceiling"].focal_change == pytest.approx(0.03, abs=0.003)
    # The repaired folder holds the room as it is now: every camera as close to the
    # changed room's truth as the stored calibration was to the first room's (the
    # repaired far2 included), the ceiling's focal length the new one.
    def errors(folder, scene) -> dict[str, float]:
        calibration = Calibration.load(folder)
        truth = CameraPoses({c.name: (c.R, c.t) for c in scene.cameras}, "m")
        return {n: e.rotation_deg for n, e in compare(CameraPoses(calibration.poses, "m"), truth).cameras.items()}

    before, after = errors(room["folder"] / "results", room["scene"]), errors(out, room["changed"])
    assert all(after[name] <= 1.5 * before[name] + 0.003 for name in before), (before, after)
    assert after["far2"] < 0.01
    K = load_intrinsics_dir(out / "intrinsics")["ceiling"].K
    assert K[0, 0] == pytest.approx(room["changed"].camera("ceiling").fx, rel=0.002)
    document = json.loads((out / CHECK_FILE).read_text())
    assert document["schema"] == "calibproj.check/1" and document["cameras"]["far2"]["status"] == "moved"
    # The repaired folder says how accurate it is: the ceiling's new focal length is in
    # its covariance, and the repaired cameras are known less well than before.
    uncertainty = json.loads((out / "uncertainty.json").read_text())
    was = json.loads((room["folder"] / "results" / "uncertainty.json").read_text())
    lens_blocks = dict(zip(uncertainty["pose_covariance"]["cameras"], uncertainty["pose_covariance"]["lens_block"]))
    assert [name for name, block in lens_blocks.items() if block is not None] == ["ceiling"]
    assert "ceiling" in uncertainty["intrinsics"]
    now = {camera["name"]: camera["projection_sigma_px"]["max"] for camera in uncertainty["cameras"]}
    before = {camera["name"]: camera["projection_sigma_px"]["max"] for camera in was["cameras"]}
    assert now["far2"] > before["far2"] and now["ceiling"] > before["ceiling"]
    assert now["far1"] == before["far1"]
    # The report shows the check: which cameras changed and the residuals before and after.
    page = (out / "report.html").read_text()
    assert "Check against the stored calibration" in page
    row = page[page.index('<td class="name">far2</td>'):][:400]
    assert "moved" in row and "&rarr;" in row


def test_a_moved_floor_or_projector_is_not_repaired_against(room, tmp_path) -> None:
    """Every camera moved (as when the projector or the floor did): no majority agrees
    with the stored calibration, so nothing is repaired and the message says why."""
    from calibproj.check.repair import check
    from calibproj.simulate import simulate_tracks
    from calibproj.simulate.scene import CameraChange
    from calibproj.sequence import Sequence

    everything = room["scene"].changed({name: CameraChange(pan_deg=0.4) for name in room["scene"].camera_names})
    tracks = simulate_tracks(everything, tmp_path / "moved", noise_px=0.1, seed=8,
                             layout=Sequence.load(room["folder"] / "sequence.json")).tracks
    result = check(room["folder"] / "results", tracks)
    assert not result.trusted and "run a full calibration" in result.message
    with pytest.raises(ValueError, match="nothing was repaired"):
        check(room["folder"] / "results", tracks, out=tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_a_covered_camera_is_not_seen_and_keeps_its_pose(room) -> None:
    from calibproj.check.repair import check
    from calibproj.formats.tracks import Tracks

    kept = room["kept"].tracks
    others = kept.camera_index != kept.camera_names.index("near1")
    covered = Tracks.from_observations(kept.camera_names, kept.camera_index[others],
                                       kept.point_ids[kept.point_index[others]], kept.xy[others],
                                       kept.markers_per_array)
    result = check(room["folder"] / "results", covered)
    assert result.cameras["near1"].status == "not seen" and "keeps its stored pose" in result.cameras["near1"].reason
    assert result.trusted


def test_the_command_prints_the_verdicts_and_exits_by_them(room, tmp_path) -> None:
    from test_pipeline import run_cli

    results, again = room["folder"] / "results", room["folder"] / "again" / "tracks.json"
    checked = run_cli("check", str(results), "--tracks", str(again))
    assert checked.returncode == 3, checked.stderr
    lines = {line.split()[0]: line for line in checked.stdout.splitlines() if line.split()}
    assert lines["far2"].split()[1] == "moved" and lines["ceiling"].split()[1] == "rezoomed"
    assert lines["far1"].split()[1] == "unchanged"
    repaired = run_cli("check", str(results), "--tracks", str(again), "--out", str(tmp_path / "new"), "--json",
                       "--no-report")
    assert repaired.returncode == 0, repaired.stderr
    assert json.loads(repaired.stdout)["cameras"]["far2"]["status"] == "moved"
    assert (tmp_path / "new" / "check.json").is_file() and (tmp_path / "new" / "camera_poses.json").is_file()
    # A tolerance no change reaches confirms every camera.
    lenient = run_cli("check", str(results), "--tracks", str(again), "--tolerance-px", "1000")
    assert lenient.returncode == 0 and "moved" not in lenient.stdout
    kept = run_cli("check", str(results), "--tracks", str(room["folder"] / "kept" / "tracks.json"))
    assert kept.returncode == 0 and "6 of 6 cameras unchanged" in kept.stdout


def test_the_native_check_prints_writes_and_exits_as_the_python_command(room, tmp_path) -> None:
    """calibproj-native check runs the same core (verdicts, repair, check.json, table,
    exit status): the same output and the same repaired files, byte for byte."""
    from test_native import find_native
    from test_pipeline import run_cli

    native = find_native()
    results, again = room["folder"] / "results", room["folder"] / "again" / "tracks.json"
    for extra in ([], ["--tolerance-px", "1000"]):
        python = run_cli("check", str(results), "--tracks", str(again), *extra)
        alone = subprocess.run([str(native), "check", str(results), "--tracks", str(again), *extra],
                               capture_output=True, text=True)
        assert (alone.returncode, alone.stdout) == (python.returncode, python.stdout), alone.stderr
    run_cli("check", str(results), "--tracks", str(again), "--out", str(tmp_path / "python"), "--no-report")
    alone = subprocess.run([str(native), "check", str(results), "--tracks", str(again), "--out",
                            str(tmp_path / "native"), "--json"], capture_output=True, text=True)
    assert alone.returncode == 0, alone.stderr
    assert json.loads(alone.stdout)["cameras"]["far2"]["status"] == "moved"
    for name in ("check.json", "camera_poses.json", "metrics.json", "points.ply", "tracks.json",
                 "intrinsics/ceiling.json", "intrinsics/far2.json", "uncertainty.json"):
        assert (tmp_path / "native" / name).read_bytes() == (tmp_path / "python" / name).read_bytes(), name
    # Both record where the repair came from, with the core's writer: the same record but
    # for when, by which command, and the Python version.
    records = [json.loads((tmp_path / tool / "provenance.json").read_text()) for tool in ("python", "native")]
    for record in records:
        for key in ("created", "command", "python"):
            record.pop(key, None)
    assert records[0] == records[1] and records[1]["inputs"]["checked"]["path"] == str(results.absolute())
    # Tracks of other points than the calibrated ones: one line naming the file, status 2.
    from calibproj.formats.tracks import Tracks

    tracks = Tracks.read(again)
    Tracks.from_observations(tracks.camera_names, np.asarray(tracks.camera_names)[tracks.camera_index],
                             tracks.point_ids[tracks.point_index] + 10 ** 6, tracks.xy,
                             tracks.markers_per_array).write(tmp_path / "stranger.json")
    stranger = subprocess.run([str(native), "check", str(results), "--tracks", str(tmp_path / "stranger.json")],
                              capture_output=True, text=True)
    assert stranger.returncode == 2 and stranger.stderr.count("\n") == 1, stranger.stderr
    assert "stranger.json" in stranger.stderr and "none of the calibrated points" in stranger.stderr


def test_the_check_projection_is_short_and_tests_every_camera(room, tmp_path) -> None:
    from test_pipeline import run_cli

    from calibproj.check.repair import check
    from calibproj.sequence import Sequence
    from calibproj.simulate import simulate_tracks

    planned = run_cli("generate", "--check", str(room["folder"] / "results"), "--sequence",
                      str(room["folder"] / "sequence.json"), "--out", str(tmp_path / "check"), "--no-video", "--json")
    assert planned.returncode == 0, planned.stderr
    summary = json.loads(planned.stdout)
    assert summary["seconds"] <= 8.0
    assert min(summary["points"][name] for name in ("far1", "far2", "far4", "far5", "near1")) >= 30
    assert summary["points"]["ceiling"] >= 6  # of the few its first projection gave it
    first = Sequence.load(room["folder"] / "sequence.json")
    # The time the points leave is spent where it sharpens the tests most: the cameras'
    # points spread over their views, so that a smaller move of the working volume shows.
    from calibproj.sequence.check_sequence import CheckSequenceOptions, plan_check

    def resolution(**options):
        return plan_check(room["folder"] / "results", [first], CheckSequenceOptions(max_seconds=12.0, **options))[2]

    spread, points_only = resolution(), resolution(target_shift_px=1000.0)
    assert all(spread[name] < 0.8 * points_only[name] for name in ("far1", "far2", "far4", "far5", "near1"))
    assert max(spread[name] for name in ("far1", "far2", "far4", "far5")) < 0.2
    assert summary["resolution_px"]["far1"] == pytest.approx(points_only["far1"], abs=1e-4)  # 8 s: points only
    sequence = Sequence.load(tmp_path / "check" / "sequence.json")
    assert len(sequence.patterns) < len(first.patterns)
    # Recorded in the changed room, it finds the changes as the full projection does.
    tracks = simulate_tracks(room["changed"], tmp_path / "recorded", noise_px=0.1, seed=9, layout=sequence).tracks
    result = check(room["folder"] / "results", tracks)
    assert {n: v.status for n, v in result.cameras.items() if v.status != "unchanged"} == {
        "far2": "moved", "ceiling": "rezoomed"}, {n: v.reason for n, v in result.cameras.items()}


def test_against_its_own_observations_a_weak_camera_is_tested_as_closely_as_the_others(stored) -> None:
    """A stored pose known only to 0.1 deg relative to the other cameras still fits its
    own calibration's observations closely: against those, a 0.1 deg turn is a move,
    and many unchanged recordings are all unchanged."""
    rng = np.random.default_rng(11)
    reference = project(stored["K"], stored["R"], stored["t"], stored["points"]) + rng.normal(0, 0.1, (63, 2))
    weak = {"rotation_sigma": math.radians(0.1), "centre_sigma": 0.01}

    def verdict(R, t, seed):
        observed = project(stored["K"], R, t, stored["points"]) + np.random.default_rng(seed).normal(0, 0.1, (63, 2))
        return _core.check.check_camera(stored["K"], stored["R"], stored["t"], weak["rotation_sigma"],
                                        weak["centre_sigma"], stored["points"], observed, stored["volume"], WIDTH,
                                        HEIGHT, stored["points"], reference)

    R, t = turned(stored, [0.0, 1.0, 0.0], 0.1)
    moved = verdict(R, t, 1)
    assert moved.status == "moved" and moved.reference == "its calibration's observations"
    assert moved.rotation_change_deg == pytest.approx(0.1, abs=0.02)
    assert all(verdict(stored["R"], stored["t"], seed).status == "unchanged" for seed in range(2, 42))


def test_a_rendered_check_projection_finds_the_turned_camera(tmp_path) -> None:
    """Videos end to end: the small room rendered and calibrated, the check projection
    planned from it (short light codes) and rendered again with one camera turned by
    0.3 deg; the check synchronises every camera and finds that one moved."""
    from calibproj.check.repair import check
    from calibproj.pipeline import calibrate
    from calibproj.sequence import generate
    from calibproj.sequence.check_sequence import plan_check
    from calibproj.simulate.render import simulate_videos
    from calibproj.simulate.scene import CameraChange, load_scene

    sequence = generate(tmp_path / "sequence", arrays=12, scales=(3.0, 5.0, 8.0), video=False)
    simulate_videos("small", sequence, tmp_path / "room", seed=1)
    calibrate(tmp_path / "room" / "videos", tmp_path / "room" / "intrinsics", sequence=tmp_path / "sequence" /
              "sequence.json", out=tmp_path / "results", progress=False, report=False)
    planned, seen, _ = plan_check(tmp_path / "results", [sequence])
    planned.save(tmp_path / "check.json")
    assert planned.duration_s <= 8.0 and min(seen.values()) >= 30
    scene = load_scene("small")
    turned = scene.camera_names[0]
    simulate_videos(scene.changed({turned: CameraChange(pan_deg=0.3)}), planned, tmp_path / "again", seed=2)
    result = check(tmp_path / "results", tmp_path / "again" / "videos", sequence=tmp_path / "check.json",
                   progress=False)
    assert result.trusted
    assert {name: verdict.status for name, verdict in result.cameras.items()} == {
        name: "moved" if name == turned else "unchanged" for name in scene.camera_names}, \
        {name: verdict.reason for name, verdict in result.cameras.items()}
    assert result.cameras[turned].rotation_change_deg == pytest.approx(0.3, abs=0.03)


def test_a_camera_turned_and_rezoomed_is_rezoomed_with_both_refitted(stored) -> None:
    R, t = turned(stored, [1.0, 0.2, 0.0], 0.4)
    K = stored["K"].copy()
    K[:2, :2] *= 0.97
    verdict = check(stored, K, R, t)
    assert verdict.status == "rezoomed" and "focal length and pose" in verdict.reason
    assert verdict.focal_scale == pytest.approx(0.97, abs=0.003)
    assert np.degrees(np.arccos(np.clip((np.trace(verdict.R @ R.T) - 1) / 2, -1, 1))) < 0.02


def test_a_rezoomed_camera_keeps_its_stored_pose(stored) -> None:
    K = stored["K"].copy()
    K[:2, :2] *= 1.02
    verdict = check(stored, K, stored["R"], stored["t"])
    assert verdict.status == "rezoomed" and verdict.focal_scale == pytest.approx(1.02, abs=0.002)
    np.testing.assert_allclose(verdict.R, stored["R"], atol=1e-12)
    np.testing.assert_allclose(verdict.t, stored["t"], atol=1e-12)


WIDE_LENS = np.array([-0.2574, 0.0891, 0.000297, -0.000198, -0.01188])  # the demo's far cameras


def as_ingested(pixels: np.ndarray, K_true: np.ndarray, K_stored: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Undistorted pixels of the true camera as the ingest makes them with the stored
    intrinsics: distorted through the true lens, undistorted with the stored one."""
    rays = np.column_stack([(pixels - K_true[:2, 2]) / np.diag(K_true)[:2], np.ones(len(pixels))])
    raw, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), K_true, dist)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    return cv2.undistortPointsIter(raw, K_stored, dist, None, K_stored, criteria).reshape(-1, 2)


def test_a_rezoomed_wide_angle_camera_keeps_its_pose() -> None:
    """Zoomed 4 % out behind a strong barrel distortion, a wide camera's pixels undistorted
    with its stored focal length are no pinhole image of the new one (px off towards the
    corners): the focal length alone explains them only through the lens, and then the
    pose stays as it was (fitted in undistorted pixels: pose and focal length both
    changed, the centre moved 4 cm, 0.8 px left)."""
    wide = floor_camera(610.0, np.linspace(-2.4, 2.4, 11), np.linspace(-1.5, 1.4, 9))
    K_stored, R, t, floor, volume = (wide[key] for key in ("K", "R", "t", "points", "volume"))
    K = K_stored.copy()
    K[:2, :2] *= 0.96
    observed = as_ingested(project(K, R, t, floor), K, K_stored, WIDE_LENS)
    observed += np.random.default_rng(3).normal(0.0, 0.1, observed.shape)
    verdict = _core.check.check_camera(K_stored, R, t, 1e-4, 1e-3, floor, observed, volume, WIDTH, HEIGHT,
                                       dist=WIDE_LENS.tolist())
    assert verdict.status == "rezoomed" and "re-zoomed" in verdict.reason, verdict.reason
    assert verdict.focal_scale == pytest.approx(0.96, abs=0.0005)
    np.testing.assert_allclose(verdict.t, t, atol=1e-12)
    assert verdict.rms_after_px < 0.2


def test_a_repaired_rezoomed_camera_gets_its_pixels_undistorted_with_its_new_focal_length(room) -> None:
    """The repaired results folder holds the re-zoomed camera's new focal length and its
    observations undistorted with it, as a calibration of the new room would."""
    from calibproj.formats.calibration import Calibration
    from calibproj.check.repair import check_cameras, repaired
    from calibproj.formats.intrinsics import load_intrinsics_dir
    from calibproj.sequence import Sequence
    from calibproj.simulate import simulate_tracks
    from calibproj.simulate.scene import CameraChange
    from calibproj.formats.tracks import Tracks

    results = room["folder"] / "results"
    stored_intrinsics = load_intrinsics_dir(results / "intrinsics")
    zoomed = room["scene"].changed({"far4": CameraChange(zoom=0.96)})
    sequence = Sequence.load(room["folder"] / "sequence.json")
    new = simulate_tracks(zoomed, room["folder"] / "zoomed", noise_px=0.1, seed=9, layout=sequence).tracks
    K_true = zoomed.camera("far4").K
    K_stored, dist = stored_intrinsics["far4"].K, stored_intrinsics["far4"].dist.ravel()
    names = np.asarray(new.camera_names)[new.camera_index]
    xy = new.xy.copy()
    xy[names == "far4"] = as_ingested(xy[names == "far4"], K_true, K_stored, dist)
    ingested = Tracks.from_observations(new.camera_names, names, new.point_ids[new.point_index], xy,
                                        new.markers_per_array)
    calibration = Calibration.load(results)
    stored_tracks = Tracks.read(results / "tracks.json")
    result = check_cameras(calibration, stored_intrinsics, ingested, stored_tracks=stored_tracks)
    assert result.cameras["far4"].status == "rezoomed", result.cameras["far4"].reason
    fixed, intrinsics, tracks = repaired(calibration, stored_intrinsics, stored_tracks, ingested, result, 0.05)
    assert intrinsics["far4"].K[0, 0] == pytest.approx(K_true[0, 0], rel=0.001)
    np.testing.assert_allclose(fixed.poses["far4"][1], calibration.poses["far4"][1], atol=1e-12)
    ids, pixels = tracks.observations("far4")
    expected_ids, expected = new.observations("far4")
    np.testing.assert_array_equal(ids, expected_ids)
    # Undistorted again with the estimated focal length (0.1 % from the true one).
    assert np.abs(pixels - expected).max() < 0.05


def test_a_repaired_camera_is_as_uncertain_as_the_repair_says(room) -> None:
    """The repaired covariance of the moved camera's pose and of the re-zoomed camera's
    focal length (its new lens block) matches their scatter over 30 draws of the check's
    noise (0.5 px on both cameras); the other cameras' blocks stay the stored ones."""
    import cv2

    from calibproj.formats.calibration import Calibration
    from calibproj.check.repair import _with_stored_uncertainty, check_cameras, repaired
    from calibproj.formats.intrinsics import load_intrinsics_dir
    from calibproj.formats.tracks import Tracks

    results, again = room["folder"] / "results", room["again"].tracks
    calibration = _with_stored_uncertainty(results, Calibration.load(results))
    assert calibration.uncertainty is not None
    stored = np.array(calibration.uncertainty.covariance)
    intrinsics, stored_tracks = load_intrinsics_dir(results / "intrinsics"), Tracks.read(results / "tracks.json")
    names = np.asarray(again.camera_names)[again.camera_index]
    rng = np.random.default_rng(1)
    poses, focals, added, focal_variances = [], [], [], []
    for _ in range(30):
        xy = again.xy + rng.normal(0.0, 0.5, again.xy.shape) * np.isin(names, ["far2", "ceiling"])[:, None]
        tracks = Tracks.from_observations(again.camera_names, names, again.point_ids[again.point_index], xy,
                                          again.markers_per_array)
        result = check_cameras(calibration, intrinsics, tracks, stored_tracks=stored_tracks)
        if [result.cameras[name].status for name in ("far2", "ceiling")] != ["moved", "rezoomed"]:
            continue  # at this noise the ceiling's zoom passes for a move in 4 % of checks
        fixed, fixed_intrinsics, _ = repaired(calibration, intrinsics, stored_tracks, tracks, result, 0.05)
        uncertainty = fixed.uncertainty
        cameras, covariance = list(uncertainty.cameras), np.array(uncertainty.covariance)
        k, ceiling = cameras.index("far2"), cameras.index("ceiling")
        unchanged = [6 * i + j for i, name in enumerate(cameras) if name not in ("far2", "ceiling") for j in range(6)]
        np.testing.assert_array_equal(covariance[np.ix_(unchanged, unchanged)], stored[np.ix_(unchanged, unchanged)])
        added.append(covariance[6 * k:6 * k + 6, 6 * k:6 * k + 6] - stored[6 * k:6 * k + 6, 6 * k:6 * k + 6])
        focal = 6 * len(cameras) + 8 * list(uncertainty.lens_block)[ceiling]
        focal_variances.append(covariance[focal, focal])
        poses.append(fixed.poses["far2"])
        focals.append(fixed_intrinsics["ceiling"].K[0, 0])
    assert len(poses) >= 25
    # [dtheta, dt] of each repaired pose about the first, as the covariance defines them.
    first = poses[0][0]
    scatter = np.array([np.concatenate([cv2.Rodrigues(R @ first.T)[0].ravel(), t]) for R, t in poses])
    empirical, predicted = np.cov(scatter.T), np.mean(added, axis=0)
    assert 0.7 < np.sqrt(np.trace(empirical[:3, :3]) / np.trace(predicted[:3, :3])) < 1.4
    assert 0.7 < np.sqrt(np.trace(empirical[3:, 3:]) / np.trace(predicted[3:, 3:])) < 1.4
    assert 0.7 < np.std(focals, ddof=1) / np.sqrt(np.mean(focal_variances)) < 1.4


@pytest.mark.parametrize("damage", ["garbage", "other cameras"])
def test_a_bad_stored_uncertainty_costs_only_the_repaired_one(room, tmp_path, damage: str) -> None:
    """Both commands repair as before and say in one line why the repaired folder has no
    uncertainty.json."""
    import shutil

    from test_native import find_native
    from test_pipeline import run_cli

    results = tmp_path / "results"
    shutil.copytree(room["folder"] / "results", results)
    path = results / "uncertainty.json"
    if damage == "garbage":
        path.write_text('{"schema": "calibproj.uncertainty/1", "pose_covariance": [')
    else:
        document = json.loads(path.read_text())
        document["pose_covariance"]["cameras"][0] = "stranger"
        document["gauge"]["reference_camera"] = "stranger"
        path.write_text(json.dumps(document))
    again = room["folder"] / "again" / "tracks.json"
    python = run_cli("check", str(results), "--tracks", str(again), "--out", str(tmp_path / "python"), "--no-report")
    native = subprocess.run([str(find_native()), "check", str(results), "--tracks", str(again), "--out",
                             str(tmp_path / "native")], capture_output=True, text=True)
    for run, out in ((python, tmp_path / "python"), (native, tmp_path / "native")):
        assert run.returncode == 0, run.stderr
        warnings = [line for line in run.stderr.splitlines() if "uncertainty.json" in line]
        assert len(warnings) == 1 and str(path) in warnings[0], run.stderr
        assert (out / "camera_poses.json").is_file() and not (out / "uncertainty.json").exists()


def test_cameras_that_cannot_be_tested_say_why_and_the_others_are(room, tmp_path) -> None:
    import shutil

    from test_pipeline import run_cli

    from calibproj.check.repair import check

    results = tmp_path / "results"
    shutil.copytree(room["folder"] / "results", results)
    # far1's intrinsics as an OpenCV YAML file without the image size; far4's broken.
    far1 = json.loads((results / "intrinsics" / "far1.json").read_text())
    (results / "intrinsics" / "far1.json").unlink()
    storage = cv2.FileStorage(str(results / "intrinsics" / "far1.yaml"), cv2.FILE_STORAGE_WRITE)
    storage.write("camera_matrix", np.array(far1["K"]))
    storage.write("distortion_coefficients", np.array(far1["dist"], float).reshape(1, -1))
    storage.release()
    result = check(results, room["again"].tracks)
    assert result.cameras["far1"].status == "unknown" and "image size" in result.cameras["far1"].reason
    assert result.cameras["far2"].status == "moved" and result.trusted  # 3 of the 5 tested unchanged
    (results / "intrinsics" / "far1.yaml").unlink()
    (results / "intrinsics" / "far1.json").write_text(json.dumps(far1))
    (results / "intrinsics" / "far4.json").write_text("{")
    result = check(results, room["again"].tracks)
    assert result.cameras["far4"].status == "unknown" and "far4.json" in result.cameras["far4"].reason
    assert result.cameras["far2"].status == "moved" and result.trusted
    # An existing --out is refused before the work, and left as it was.
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "camera_poses.json").write_text("{}")
    taken = run_cli("check", str(results), "--tracks", str(room["folder"] / "again" / "tracks.json"),
                    "--out", str(tmp_path / "taken"))
    assert taken.returncode == 2 and "--force" in taken.stderr
    assert (tmp_path / "taken" / "camera_poses.json").read_text() == "{}"
    # Only one camera seen: nothing can be said against the calibration (exit 3, not 4).
    kept = room["kept"].tracks
    alone = kept.camera_index == kept.camera_names.index("far4")
    from calibproj.formats.tracks import Tracks

    Tracks.from_observations(kept.camera_names, kept.camera_index[alone], kept.point_ids[kept.point_index[alone]],
                             kept.xy[alone], kept.markers_per_array).write(tmp_path / "alone.json")
    lone = run_cli("check", str(results), "--tracks", str(tmp_path / "alone.json"))
    assert lone.returncode == 3 and "too few to tell" in lone.stdout
