"""Real cameras against the renderer's truth. Frame timing: dropped frames and
timestamp jitter (the frame grid from container timestamps, light-code search over
the frames present, an ingest that keeps sync and picks clean frames). Rolling
shutters: the readout measured from image bands, the first row's frame map, picks
clean in every row."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibproj import _core
from calibproj.sequence.builder import build_sequence
from calibproj.sequence.video import GreyVideoWriter
from calibproj.ingest.videos import ingest
from calibproj.simulate.render import simulate_videos
from calibproj.simulate.people import ProjectorLight, blocked, surface_points
from calibproj.simulate.render import RenderOptions
from calibproj.simulate.scene import Person, Projector, load_scene

MAX_SYNC_ERROR_FRAMES = 0.1
DROP_RATE = 0.04
JITTER_S = 0.0015
READOUT_S = 0.02
# An observation this far from its marker's true position belongs to another marker.
WRONG_PX = 3.0
MAX_READOUT_ERROR_S = 0.002


def grid_times(rng, slots: int, fps: float, drop_rate: float, jitter_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Slots kept (the first always) and their jittered times, relative to the first."""
    kept = np.flatnonzero(np.r_[True, rng.random(slots - 1) >= drop_rate])
    times = kept / fps + rng.normal(0.0, jitter_s, len(kept))
    return kept, times - times[0]


@pytest.mark.parametrize("fps", [25.0, 29.97, 30.0, 59.94])
def test_frame_period_from_timestamps_with_gaps_and_jitter(fps):
    rng = np.random.default_rng(int(fps))
    _, times = grid_times(rng, 120, fps, drop_rate=0.1, jitter_s=0.04 / fps)
    period = _core.video.frame_period(list(rng.permutation(times)))
    assert abs(period * fps - 1.0) < 2e-3
    assert _core.video.frame_period([0.0, 1.0]) == 0.0


def test_a_retimed_video_has_gaps_where_frames_were_dropped(tmp_path):
    rng = np.random.default_rng(5)
    kept, times = grid_times(rng, 90, 30.0, DROP_RATE * 4, JITTER_S)
    path = tmp_path / "dropping.mp4"
    with GreyVideoWriter(path, (64, 48), 30.0, crf=0, preset="ultrafast", timestamps_s=times) as writer:
        for slot in kept:
            writer.write(np.full((48, 64), 40 + 2 * int(slot), np.uint8))
    decoded = _core.video.frame_timestamps(str(path))
    assert np.max(np.abs(decoded - times)) < 2e-5  # the 1/90000 s time base
    info = _core.video.probe(str(path))
    assert info.timed and info.fps == pytest.approx(30.0)
    signal = _core.video.luma_signal(str(path), 1.0, 1)
    assert len(signal) == kept[-1] + 1
    np.testing.assert_array_equal(np.flatnonzero(~np.isnan(signal)), kept)
    np.testing.assert_allclose(signal[kept] * 255.0, 40 + 2 * kept, atol=1.5)  # limited-range rounding
    # Decoding order as time: every frame after the first gap is misplaced.
    assert not np.isnan(_core.video.luma_signal(str(path), 1.0, 1, use_timestamps=False)).any()


def test_writer_rejects_timestamps_that_go_back(tmp_path):
    with pytest.raises(ValueError, match="increasing"):
        GreyVideoWriter(tmp_path / "x.mp4", (64, 48), 30.0, timestamps_s=[0.0, 0.1, 0.05])


def test_a_timestamp_jump_fails_the_camera_with_a_clear_message(tmp_path):
    path = tmp_path / "paused.mp4"
    times = np.r_[np.arange(20) / 30.0, 60.0 + np.arange(20) / 30.0]
    with GreyVideoWriter(path, (64, 48), 30.0, crf=0, preset="ultrafast", timestamps_s=times) as writer:
        for _ in times:
            writer.write(np.zeros((48, 64), np.uint8))
    with pytest.raises(RuntimeError, match=r"paused\.mp4: the timestamps jump by 59\.3.* s after frame 19"):
        _core.video.luma_signal(str(path))


def small_room_with(out, **camera_changes):
    """The small room, every camera changed alike, rendered and ingested."""
    sequence = build_sequence(markers="aruco:4X4_50", arrays=4, scales=(1.0, 2.0, 3.0), marker_px=48.0,
                              code_degree=4, reference_frames=8)
    small = load_scene("small", seed=7)
    cameras = tuple(replace(camera, **camera_changes) for camera in small.cameras)
    simulate_videos(replace(small, cameras=cameras), sequence, out, seed=7)
    truth = json.loads((out / "truth.json").read_text())
    result = ingest(out / "videos", sequence, out / "intrinsics", progress=False)
    return sequence, truth, result


def assert_records_from_clean_frames(result, truth) -> None:
    for name, camera in result.cameras.items():
        records = camera.raw.records
        clean = truth["clean_frames"][name]
        for pattern, first, count in zip(records.pattern, records.first_frame, records.frame_count):
            assert set(range(first, first + count)) <= set(clean[pattern]), name


@pytest.fixture(scope="module")
def dropping(tmp_path_factory):
    """The small room whose cameras drop frames and jitter, with true timestamps."""
    return small_room_with(tmp_path_factory.mktemp("dropping"), drop_rate=DROP_RATE, frame_jitter_s=JITTER_S)


@pytest.fixture(scope="module")
def rolling(tmp_path_factory):
    """The small room with rolling shutters (20 ms readout)."""
    return small_room_with(tmp_path_factory.mktemp("rolling"), readout_s=READOUT_S)


def test_dropped_frames_keep_sync_to_a_tenth_of_a_frame(dropping):
    _, truth, result = dropping
    assert not result.failed
    for name, camera in result.cameras.items():
        timing = truth["timing"]["cameras"][name]
        assert timing["dropped_frames"], name  # the seed drops some frames in every camera
        sync = camera.raw.sync
        offset = -timing["first_exposure_start_s"] * timing["fps"]
        assert abs(sync.map.offset - offset) <= max(MAX_SYNC_ERROR_FRAMES, sync.offset_uncertainty), name
        # The rate error, as the drift it makes over the whole sequence, camera frames.
        drift = abs(sync.map.rate - timing["fps_ratio"]) * truth["timing"]["sequence_frames"]
        assert drift < MAX_SYNC_ERROR_FRAMES, name


def test_dropped_frames_and_jitter_are_reported(dropping):
    _, truth, result = dropping
    report = result.report()["cameras"]
    for name, camera in result.cameras.items():
        timing = truth["timing"]["cameras"][name]
        frames = report[name]["frames"]
        # Decoding stops after the end code's window: drops are counted up to there.
        assert timing["recorded_frames"] - 40 < frames["decoded"] <= timing["recorded_frames"]
        recorded = np.setdiff1d(np.arange(timing["frame_count"]), timing["dropped_frames"])
        last_slot = recorded[frames["decoded"] - 1]
        assert frames["dropped"] == sum(1 for slot in timing["dropped_frames"] if slot < last_slot)
        assert frames["duplicated"] == 0
        assert frames["jitter_ms"] == pytest.approx(1e3 * np.std(timing["jitter_s"]), rel=0.25)
        assert report[name]["video_info"]["fps"] == pytest.approx(timing["fps"], rel=1e-4)


def test_detections_come_from_recorded_clean_frames_and_only_drops_lose_patterns(dropping):
    """Picked frames the camera dropped are replaced by later clean ones: a pattern is
    lost only where a drop hit its few clean frames, and every frame detected on shows
    one pattern only."""
    _, truth, result = dropping
    assert_records_from_clean_frames(result, truth)
    for name, camera in result.cameras.items():
        raw = camera.raw
        clean = truth["clean_frames"][name]
        dropped = set(truth["timing"]["cameras"][name]["dropped_frames"])
        # Patterns with a dropped frame among their clean frames or next to them.
        hit = sum(1 for frames in clean if frames and dropped & set(range(frames[0] - 1, frames[-1] + 2)))
        assert raw.patterns_missing + raw.patterns_dropped <= hit, name
        handled = sum(s.detected_patterns + s.skipped_patterns for s in raw.scales)
        assert handled >= sum(1 for frames in clean if frames) - hit, name


def test_rolling_shutter_readout_is_measured_and_sync_is_the_first_rows(rolling):
    """cam3 (29.97 fps) sees light changes at every phase: its readout is measured to a
    fraction of a millisecond. cam2 (25 fps) sees them at five phases only, so the codes
    fix its readout only relative to its unknown exposure: its sigma says how much that
    leaves open, and holds the truth. cam1 (30 fps, starting on a projector frame
    change) sees none in any row and keeps an offset interval that holds the truth."""
    _, truth, result = rolling
    assert not result.failed
    report = result.report()["cameras"]
    for name, camera in result.cameras.items():
        timing = truth["timing"]["cameras"][name]
        sync = camera.raw.sync
        offset = -timing["first_exposure_start_s"] * timing["fps"]
        assert abs(sync.map.offset - offset) <= max(MAX_SYNC_ERROR_FRAMES, sync.offset_uncertainty), name
    cam2, cam3 = report["cam2"]["sync"], report["cam3"]["sync"]
    assert abs(cam3["readout_s"] - READOUT_S) < MAX_READOUT_ERROR_S
    assert cam3["readout_sigma_s"] < MAX_READOUT_ERROR_S / 2
    assert abs(cam2["readout_s"] - READOUT_S) <= 2.0 * cam2["readout_sigma_s"]
    assert cam2["readout_sigma_s"] > cam3["readout_sigma_s"]


def test_a_known_exposure_measures_the_readout_of_a_camera_seeing_few_phases(rolling):
    """With its exposure time given (calibrate/detect --exposure), cam2's bands tell its
    readout itself: within 2 ms of the truth and known to 1 ms, its sync to a tenth of
    a frame."""
    sequence, truth, result = rolling
    videos = Path(result.cameras["cam2"].video).parent
    exposures = {name: truth["timing"]["cameras"][name]["exposure_s"] for name in ("cam2", "cam3")}
    given = ingest(videos, sequence, videos.parent / "intrinsics", progress=False, exposures=exposures)
    report = given.report()["cameras"]
    for name in exposures:
        sync = report[name]["sync"]
        assert abs(sync["readout_s"] - READOUT_S) < MAX_READOUT_ERROR_S, name
        assert sync["readout_sigma_s"] < MAX_READOUT_ERROR_S / 2, name
        timing = truth["timing"]["cameras"][name]
        offset = -timing["first_exposure_start_s"] * timing["fps"]
        assert abs(given.cameras[name].raw.sync.map.offset - offset) <= MAX_SYNC_ERROR_FRAMES, name


def test_rolling_shutter_picks_frames_clean_in_every_row(rolling):
    _, truth, result = rolling
    assert_records_from_clean_frames(result, truth)
    for camera in result.cameras.values():
        assert len(camera.raw.centres.array) > 40


def test_a_global_shutter_reads_out_in_no_time(dropping):
    _, _, result = dropping
    readout = result.report()["cameras"]["cam2"]["sync"]
    assert readout["readout_s"] is not None
    assert abs(readout["readout_s"]) < max(MAX_READOUT_ERROR_S, 3 * readout["readout_sigma_s"])


# ---------------------------------------------------------------- renderer effects

def test_floor_texture_multiplies_the_light_by_the_floor_albedo():
    """With every other effect off, a textured floor's frame is the plain floor's frame
    times the albedo the texture gives at each pixel's floor point: darker along the
    grout lines (every tile_m metres) and under stains."""
    from calibproj.simulate.floor_texture import floor_albedo
    from calibproj.simulate.render import IDEAL_PHOTOMETRIC, RenderOptions, render_stills
    from calibproj.simulate.scene import FloorTexture
    from calibproj.simulate.warp import floor_view

    sequence = build_sequence(arrays=1, scales=(10.0,), grid=(2, 4), code_degree=3, reference_frames=3)
    plain = replace(load_scene("small"), photometric=IDEAL_PHOTOMETRIC)
    texture = FloorTexture(tile_m=0.5, grout_m=0.01, grout_albedo=0.3, stains=40, stain_radius_m=0.2)
    textured = replace(plain, floor=replace(plain.floor, texture=texture))
    options = RenderOptions(photometric=IDEAL_PHOTOMETRIC)
    base = render_stills(plain, sequence, 0, cameras=["cam1"], options=options)["cam1"].astype(float)
    seen = render_stills(textured, sequence, 0, cameras=["cam1"], options=options)["cam1"].astype(float)
    view = floor_view(plain.camera("cam1"), plain.projector, plain.floor)
    albedo = floor_albedo(texture, view.floor_x, view.floor_y, view.floor_footprint)
    lit = base > 200
    assert lit.sum() > 1000
    np.testing.assert_allclose(seen[lit], np.minimum(base[lit] * albedo[lit], 255.0), atol=1.0)
    assert albedo[lit].min() < 0.8 and np.median(albedo[lit]) > 0.9


def test_automatic_exposure_brings_the_mean_to_its_target(tmp_path):
    """The gain follows the frames' brightness within its limits; the truth lists it."""
    from calibproj.simulate.scene import AutoExposure

    sequence = build_sequence(arrays=2, scales=(6.0, 10.0), grid=(2, 4), code_degree=3, reference_frames=3)
    small = load_scene("small")
    control = AutoExposure(target=0.5, time_constant_s=0.1, min_gain=0.5, max_gain=4.0)
    scene = replace(small, cameras=(replace(small.cameras[0], auto_exposure=control),))
    simulate_videos(scene, sequence, tmp_path, seed=3)
    gains = np.array(json.loads((tmp_path / "truth.json").read_text())["timing"]["cameras"]["cam1"]["gains"])
    signal = _core.video.luma_signal(str(tmp_path / "videos" / "cam1.mp4"), 1.0, 1)
    assert len(gains) == len(signal)
    assert gains.min() >= 0.5 and gains.max() <= 4.0 and np.ptp(gains) > 0.5
    # Where the gain is within its limits, frames settle near the target brightness.
    settled = (gains > 0.55) & (gains < 3.9)
    settled[:10] = False
    assert settled.sum() > 10
    assert abs(np.median(signal[settled]) - 0.5) < 0.1


# ------------------------------------------------------- detections against the floor

def test_detections_off_the_floor_homography_are_dropped():
    """A marker read with a wrong id (or from a frame of another pattern) lands far from
    where the homography of the others puts it; with too few agreeing, none is kept."""
    rng = np.random.default_rng(2)
    H = np.array([[0.6, 0.05, 120.0], [-0.02, 0.55, 80.0], [2e-5, 1e-5, 1.0]])
    projector = rng.uniform([0, 0], [1920, 1080], (40, 2))
    mapped = np.c_[projector, np.ones(40)] @ H.T
    image = mapped[:, :2] / mapped[:, 2:] + rng.normal(0.0, 0.1, (40, 2))
    wrong = [3, 11, 27]
    image[wrong] += [230.0, -45.0]
    keep, checked, problem = _core.detect.check_floor_consistency(projector, image)
    assert checked and not problem
    np.testing.assert_array_equal(np.flatnonzero(~keep), wrong)
    keep, checked, _ = _core.detect.check_floor_consistency(projector[:5], image[:5])
    assert not checked and keep.all()  # too few to check
    scrambled = image[rng.permutation(40)]
    keep, checked, problem = _core.detect.check_floor_consistency(projector, scrambled)
    assert checked and not keep.any() and "agree with one homography of the floor" in problem


def test_a_centre_displaced_by_a_table_edge_stands_out_against_its_neighbours():
    """A lens known only roughly bends every residual smoothly, by up to 2.5 px at the
    image corners (within the homography's threshold); a marker partly hidden by a
    table is read 1.2 px off. Its neighbours' residuals predict its own, so the local
    check finds it and keeps every other detection."""
    rng = np.random.default_rng(5)
    H = np.array([[0.6, 0.05, 120.0], [-0.02, 0.55, 80.0], [2e-5, 1e-5, 1.0]])
    projector = np.array([[x, y] for x in np.linspace(100, 1800, 24) for y in np.linspace(100, 1000, 14)])
    projector += rng.uniform(-20.0, 20.0, projector.shape)
    mapped = np.c_[projector, np.ones(len(projector))] @ H.T
    image = mapped[:, :2] / mapped[:, 2:]
    offset = (image - [640.0, 360.0]) / np.hypot(640.0, 360.0)
    image += 2.5 * offset * np.sum(offset ** 2, axis=1, keepdims=True)
    image += rng.normal(0.0, 0.05, image.shape)
    displaced = [40, 170, 301]
    image[displaced] += [0.9, -0.8]
    keep, checked, problem = _core.detect.check_floor_consistency(projector, image)
    assert checked and not problem
    np.testing.assert_array_equal(np.flatnonzero(~keep), displaced)
    keep, _, _ = _core.detect.check_floor_consistency(projector, image, local_neighbours=0)
    assert keep.all()


def test_the_local_check_takes_sets_a_k_d_tree_search_comes_back_short_on():
    """The 24 centres a zoomed camera kept in a room with people (scales of one marker
    a tenth of a pixel apart): OpenCV's k-d tree search for all 24 neighbours of each
    asserted on them, and the camera failed. They are checked, and kept."""
    image = np.array([
        [593.2, 282.4], [593.1, 282.5], [499.1, 407.3], [499.1, 407.2], [406.9, 529.6], [683.2, 163.0],
        [457.8, 192.5], [363.3, 316.3], [363.5, 316.2], [270.7, 437.6], [177.1, 560.3], [135.7, 346.3],
        [1006.5, 557.0], [1095.3, 434.3], [867.5, 464.7], [774.3, 591.7], [1135.0, 100.2], [1047.8, 219.0],
        [956.8, 343.1], [956.7, 343.1], [729.8, 373.2], [729.7, 373.1], [636.1, 499.1], [910.9, 129.6]])
    H = np.array([[0.6, 0.05, 120.0], [-0.02, 0.55, 80.0], [2e-5, 1e-5, 1.0]])
    mapped = np.c_[image, np.ones(len(image))] @ np.linalg.inv(H).T
    projector = mapped[:, :2] / mapped[:, 2:]
    keep, checked, problem = _core.detect.check_floor_consistency(projector, image, local_neighbours=8)
    assert checked and not problem and keep.all()


def test_a_static_pattern_read_as_one_marker_in_every_array_is_dropped():
    """A stain decoded as marker 17 in every frame: one image point for the shifted
    centres of that marker in 15 arrays. A homography fits one position, so it cannot
    be checked: none is kept; the same marker beside others is checked and kept."""
    rng = np.random.default_rng(4)
    projector = np.array([900.0, 500.0]) + rng.uniform(-30.0, 30.0, (15, 2))
    image = np.array([226.0, 525.0]) + rng.normal(0.0, 1.0, (15, 2))
    keep, checked, problem = _core.detect.check_floor_consistency(projector, image, positions=[17] * 15)
    assert checked and not keep.any() and "1 marker position(s), too few to check" in problem
    # Too few to check (a far camera that sees 4 markers of a short extra projection,
    # as in a rendered room with a strongly textured floor): the repeats are still
    # dropped, and 4 markers at 4 places are kept unchecked.
    keep, checked, problem = _core.detect.check_floor_consistency(projector[:4], image[:4], positions=[17] * 4)
    assert not checked and not keep.any() and not problem
    spread = image[:4] + np.array([[0.0, 0.0], [40.0, 0.0], [0.0, 40.0], [40.0, 40.0]])
    keep, checked, _ = _core.detect.check_floor_consistency(projector[:4], spread, positions=[17] * 4)
    assert not checked and keep.all()
    H = np.array([[0.6, 0.05, 120.0], [-0.02, 0.55, 80.0], [2e-5, 1e-5, 1.0]])
    grid = np.array([[x, y] for x in (300.0, 900.0, 1500.0) for y in (200.0, 800.0)])
    projector = np.repeat(grid, 5, axis=0) + rng.uniform(-30.0, 30.0, (30, 2))
    mapped = np.c_[projector, np.ones(30)] @ H.T
    keep, _, problem = _core.detect.check_floor_consistency(projector, mapped[:, :2] / mapped[:, 2:],
                                                            positions=np.repeat(np.arange(6), 5).tolist())
    assert keep.all() and not problem


def test_timestamps_that_go_back_fail_the_camera_with_a_clear_message(tmp_path):
    """Two MPEG-TS recordings joined byte by byte: the second restarts the clock.
    Counting its frames as duplicates would silently lose them."""
    import subprocess

    parts = []
    for index in range(2):
        part = tmp_path / f"part{index}.ts"
        subprocess.run(["ffmpeg", "-v", "error", "-y", "-f", "lavfi", "-i", "testsrc=size=64x48:rate=30:duration=1",
                        "-c:v", "libx264", "-bf", "0", "-f", "mpegts", str(part)], check=True)
        parts.append(part.read_bytes())
    joined = tmp_path / "joined.ts"
    joined.write_bytes(b"".join(parts))
    with pytest.raises(RuntimeError, match=r"joined\.ts: the timestamps go back by 0\.9666\d* s after frame 29"):
        _core.video.luma_signal(str(joined))
    assert len(_core.video.luma_signal(str(joined), use_timestamps=False)) == 60


# ------------------------------------------------------------------------ people

# Crosses the small room's projection while the patterns play.
WALKER = Person(start=(-1.2, -0.3), end=(1.2, 0.3), start_s=2.0, speed_mps=0.5)


def test_a_person_blocks_the_rays_that_pass_through_them():
    """A camera 3 m above (0, 0) and a person of 1.7 m at (1, 0): the floor at their feet
    and just behind them (the ray passes at 1.1 m) is hidden, the floor far behind (the
    ray passes over their head, 1.75 m at the near side) and beside them is not."""
    floor_x = np.array([1.0, 2.0, 3.0, 0.0, np.nan])
    floor_y = np.array([0.0, 0.0, 0.0, 1.0, 0.0])
    hidden = blocked(np.array([0.0, 0.0, 3.0]), floor_x, floor_y, np.array([1.0, 0.0]), 0.25, 1.7)
    assert hidden.tolist() == [True, True, False, False, False]
    assert Person((0.0, 0.0), (2.0, 0.0), start_s=1.0, speed_mps=0.5).centre(3.0).tolist() == [1.0, 0.0]
    assert Person((0.0, 0.0), (2.0, 0.0), start_s=1.0).centre(0.5) is None


def test_the_body_point_a_camera_sees_is_on_the_side_or_the_top():
    """The camera 3 m above (0, 0), the person of 1.7 m, radius 0.25, at (1, 0): the ray
    to (1.5, 0) meets the near side at x = 0.75, z = 1.5; the ray to (2, 0) passes over
    the near edge (z 1.875 there) and comes in through the top at x = 1 - 0.4 / 3."""
    points, normals = surface_points(np.array([0.0, 0.0, 3.0]), np.array([[1.5, 0.0], [2.0, 0.0]]),
                                     np.array([1.0, 0.0]), 0.25, 1.7)
    np.testing.assert_allclose(points, [[0.75, 0.0, 1.5], [2.0 * (1.0 - 1.7 / 3.0), 0.0, 1.7]], atol=1e-12)
    np.testing.assert_allclose(normals, [[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], atol=1e-12)


def test_the_projection_lands_on_a_person():
    """A projector 3 m above (0, 0) looking down, its image white only at the pixel above
    (1, 0): a person's head there is lit in full (the top faces the projector), the side
    facing away from the projector is not, the side facing it gets the light times its
    incidence relative to the floor's; a content without that white pixel lights nothing."""
    projector = Projector(position=(0.0, 0.0, 3.0), look_at=(0.0, 0.0, 0.0), resolution=(64, 48), fx=40.0)
    K, R, t = projector.K, projector.R, projector.t
    head = np.array([1.0, 0.0, 1.7])
    pixel = K @ (R @ head + t)
    column, row = (np.rint(pixel[:2] / pixel[2])).astype(int)
    white = np.zeros((48, 64), np.uint8)
    white[row, column] = 255
    images = {"white": white, "dark": np.zeros_like(white)}
    light = ProjectorLight(np.array(projector.position), K, R, t, projector.resolution, images.__getitem__)
    points = np.array([head, [0.75, 0.0, 1.5], [1.25, 0.0, 1.5]])
    normals = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    lit = light.light(points, normals, {"white": 1.0}, np.zeros(3, dtype=int))
    assert lit[0] == pytest.approx(1.0) and lit[2] == 0.0  # the far side faces away
    assert light.light(points[:1], normals[:1], {"dark": 1.0}, np.zeros(1, dtype=int))[0] == 0.0
    # Half the exposure on each content (a pattern change during it): half the light.
    half = light.light(points[:1], normals[:1], {"white": 0.5, "dark": 0.5}, np.zeros(1, dtype=int))
    assert half[0] == pytest.approx(0.5)


def test_a_person_hides_the_floor_and_shades_it(tmp_path):
    """Rendered with and without the walker: the frames differ only while they are in
    the room, and there the camera sees their darker body where markers were lit."""
    sequence = build_sequence(markers="aruco:4X4_50", arrays=2, scales=(1.0,), marker_px=48.0, code_degree=4,
                              reference_frames=8)
    small = load_scene("small", seed=7).subset(["cam1"])
    frames = {}
    for name, people in (("empty", ()), ("walker", (WALKER,))):
        simulate_videos(replace(small, people=people), sequence, tmp_path / name, seed=7,
                        options=RenderOptions(crf=0, fresh_noise=False))
        capture = cv2.VideoCapture(str(tmp_path / name / "videos" / "cam1.mp4"))
        frames[name] = []
        while True:
            ok, image = capture.read()
            if not ok:
                break
            frames[name].append(image[:, :, 0].astype(float))
    difference = [np.abs(a - b).mean() for a, b in zip(frames["empty"], frames["walker"])]
    fps = small.cameras[0].fps
    walking = [WALKER.centre(i / fps) is not None for i in range(len(difference))]
    assert max(d for d, w in zip(difference, walking) if not w) < 0.01
    assert min(d for d, w in zip(difference, walking) if w) > 0.1
    # Where the walker stands over lit markers, the camera sees their darker body.
    busiest = int(np.argmax(difference))
    darker = frames["walker"][busiest] < frames["empty"][busiest] - 20
    assert darker.mean() > 0.002


# ------------------------------------------------------------- everything at once

@pytest.fixture(scope="module")
def real_room(tmp_path_factory):
    """The small room as real cameras and a real room record it: dropped frames and
    jitter, rolling shutters, automatic exposure, a tiled and stained floor, some room
    light, someone walking through the projection, and harder compression."""
    from calibproj.simulate.render import RenderOptions
    from calibproj.simulate.scene import AutoExposure, FloorTexture

    out = tmp_path_factory.mktemp("real_room")
    sequence = build_sequence(markers="aruco:4X4_50", arrays=4, scales=(1.0, 2.0, 3.0), marker_px=48.0,
                              code_degree=4, reference_frames=8)
    small = load_scene("small", seed=7)
    cameras = tuple(replace(camera, drop_rate=0.02, frame_jitter_s=0.001, readout_s=0.015,
                            auto_exposure=AutoExposure()) for camera in small.cameras)
    scene = replace(small, cameras=cameras, floor=replace(small.floor, texture=FloorTexture()),
                    photometric=replace(small.photometric, ambient=0.15, contrast=0.6), people=(WALKER,))
    simulate_videos(scene, sequence, out, seed=7, options=RenderOptions(crf=24))
    truth = json.loads((out / "truth.json").read_text())
    return truth, ingest(out / "videos", sequence, out / "intrinsics", progress=False)


def test_a_real_room_gives_right_observations_only(real_room):
    """Every camera keeps most of its markers, none assigned to a wrong marker or pattern
    (markers are farther apart than WRONG_PX), and its sync holds the truth within its
    uncertainty: widened by half the readout where it was measured but not applied, and
    where the readout could not be measured at all (the frame map is then that of rows
    near the middle) by half the largest readout a camera can have, a frame."""
    truth, result = real_room
    assert not result.failed
    for name, camera in result.cameras.items():
        points = truth["image_points"][name]
        true_xy = dict(zip(points["ids"], points["undistorted"]))
        ids, xy = result.tracks.observations(name)
        assert len(ids) > 30, name
        errors = np.array([np.hypot(*(np.asarray(p) - true_xy[int(i)])) for i, p in zip(ids, xy)])
        assert errors.max() < WRONG_PX, name  # no observation of another marker or pattern
        assert np.sqrt(np.mean(errors**2)) < 0.3, name
        timing = truth["timing"]["cameras"][name]
        sync = camera.raw.sync
        offset = -timing["first_exposure_start_s"] * timing["fps"]
        if sync.readout is None:
            assert sync.offset_uncertainty >= 0.5, name
        assert abs(sync.map.offset - offset) <= max(MAX_SYNC_ERROR_FRAMES, sync.offset_uncertainty), name
