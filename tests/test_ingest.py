"""From rendered camera videos to MSM tracks: centre accuracy against the simulation's
truth (ArUco and AprilTag), region-of-interest detection against whole frames, frame
picking, scale merging, the report and command line, and failing cameras."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import time
from dataclasses import replace
from functools import partial
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibproj import _core
from calibproj.cli.main import main
from calibproj.sequence.builder import build_sequence
from calibproj.ingest.videos import ingest
from calibproj.ingest.options import IngestOptions
from calibproj.formats.intrinsics import Intrinsics, read_intrinsics, write_intrinsics
from calibproj.sequence.markers import MarkerDetector, marker_centres, render_marker
from calibproj.sequence.video import GreyVideoWriter
from calibproj.simulate.render import simulate_videos
from calibproj.simulate.scene import load_scene
from calibproj.formats.tracks import Tracks

# Merged centres of MSMs with a marker at least this wide (detected side, pixels) must
# be within MAX_RMS_PX of the truth; smaller ones are left to the detector's own tests.
MIN_SIDE_PX = 20.0
MAX_RMS_PX = 0.1
MAX_ROI_DIFFERENCE_PX = 0.01
# The edge fit converges to within its tolerance from the prediction as from the
# detector's corners (measured on the demo room: 0.006-0.017 px RMS).
MAX_VERIFIED_RMS_DIFFERENCE_PX = 0.02


def msm_sequence(markers: str, arrays: int = 4):
    """Arrays of 4 x 8 markers at three scales (12, 24 and ~30 px in the small preset's
    cameras) with 15-bit codes: about 6 s of projection."""
    return build_sequence(markers=markers, arrays=arrays, scales=(1.0, 2.0, 3.0), marker_px=48.0, code_degree=4,
                          reference_frames=8)


def render(tmp_path_factory, name: str, markers: str, arrays: int = 4):
    out = tmp_path_factory.mktemp(name)
    sequence = msm_sequence(markers, arrays)
    simulate_videos("small", sequence, out, seed=7)
    return out, sequence, json.loads((out / "truth.json").read_text())


@pytest.fixture(scope="module")
def aruco(tmp_path_factory):
    return render(tmp_path_factory, "aruco", "aruco:4X4_50")


@pytest.fixture(scope="module")
def apriltag(tmp_path_factory):
    # One array fewer than the ArUco sequence: its videos are "of another sequence".
    return render(tmp_path_factory, "apriltag", "apriltag:tag36h11", arrays=3)


def roi_and_whole_frame(rendered):
    """Ingests with regions of interest (markers looked for at their predictions first,
    key True, and by the detector alone, key "detector") and with whole frames only
    (False). No whole frames are explored for other surfaces (there are none): with four
    arrays they would be a third of the patterns the regions are compared on."""
    out, sequence, _ = rendered
    runs = {True: {}, "detector": {"verify_predicted": False}, False: {"use_roi": False}}
    return {key: ingest(out / "videos", sequence, out / "intrinsics",
                        options=IngestOptions(explore_interval=0, **changes), progress=False)
            for key, changes in runs.items()}


@pytest.fixture(scope="module")
def aruco_results(aruco):
    return roi_and_whole_frame(aruco)


@pytest.fixture(scope="module")
def apriltag_results(apriltag):
    return roi_and_whole_frame(apriltag)


def centre_errors(result, truth, camera: str) -> tuple[np.ndarray, np.ndarray]:
    """Errors of the merged centres (px) and the largest detected side of each: an MSM
    seen large is held to MAX_RMS_PX whatever smaller scales of it are decoded too."""
    points = truth["image_points"][camera]
    true_xy = dict(zip(points["ids"], points["undistorted"]))
    raw = result.cameras[camera].raw
    records = raw.records
    markers_per_array = result.tracks.markers_per_array
    record_ids = records.array * markers_per_array + records.marker
    ids, xy = result.tracks.observations(camera)
    errors, sides = [], []
    for point_id, centre in zip(ids, xy):
        kept = (record_ids == point_id) & records.kept
        errors.append(np.linalg.norm(centre - true_xy[int(point_id)]))
        sides.append(records.side_px[kept].max())
    return np.array(errors), np.array(sides)


def check_accuracy(results, truth):
    result = results[True]
    assert not result.failed
    for camera in result.cameras:
        errors, sides = centre_errors(result, truth, camera)
        wide = sides >= MIN_SIDE_PX
        assert wide.sum() >= 30, camera
        rms = float(np.sqrt(np.mean(errors[wide] ** 2)))
        assert rms < MAX_RMS_PX, (camera, rms)


def test_the_centres_repeatability_is_reported_per_scale(aruco, aruco_results):
    """detect_report.json gives, per scale, how far its centres lie from their MSM's
    merged centre (RMS, MSMs kept at two scales or more): about the centres' own error,
    measured without the truth."""
    result = aruco_results[True]
    report = result.report()["cameras"]
    for camera in result.cameras:
        errors, sides = centre_errors(result, aruco[2], camera)
        truth_rms = float(np.sqrt(np.mean(errors[sides >= MIN_SIDE_PX] ** 2)))
        spreads = [scale for scale in report[camera]["scales"] if scale["spread_count"] > 0]
        assert spreads, camera
        for scale in spreads:
            assert 0.0 < scale["spread_px"] < 3.0 * truth_rms + 0.05, (camera, scale, truth_rms)
        assert all(scale["spread_px"] is None for scale in report[camera]["scales"] if scale["spread_count"] == 0)


def test_aruco_centres_match_the_truth(aruco, aruco_results):
    check_accuracy(aruco_results, aruco[2])


def test_apriltag_centres_match_the_truth(apriltag, apriltag_results):
    check_accuracy(apriltag_results, apriltag[2])


def check_roi_equals_whole_frame(results):
    for camera in results[True].cameras:
        roi, whole = (results[flag].cameras[camera].raw.records for flag in (True, False))
        assert roi.in_region.sum() > 0, camera
        assert not whole.in_region.any()
        # The same markers but for a few at the edge of decodability: a region is shrunk
        # to its target module size, and its contrast (which sets the threshold) is that
        # of one marker, where the whole frame's is the frame's.
        keys = [list(zip(r.pattern.tolist(), r.marker.tolist())) for r in (roi, whole)]
        common = set(keys[0]) & set(keys[1])
        assert len(common) >= 0.97 * max(len(k) for k in keys), (camera, len(keys[0]), len(keys[1]))
        first = [keys[0].index(k) for k in sorted(common)]
        second = [keys[1].index(k) for k in sorted(common)]
        assert np.abs(roi.centre[first] - whole.centre[second]).max() < MAX_ROI_DIFFERENCE_PX, camera


def test_roi_detection_equals_whole_frame_detection_aruco(aruco_results):
    check_roi_equals_whole_frame({True: aruco_results["detector"], False: aruco_results[False]})


def test_roi_detection_equals_whole_frame_detection_apriltag(apriltag_results):
    check_roi_equals_whole_frame({True: apriltag_results["detector"], False: apriltag_results[False]})


def check_verified_equals_detected(results):
    """Markers looked for at their predicted corners: every marker the detector finds in
    its region is found, and its centre comes from the same edge fit started elsewhere."""
    for camera in results[True].cameras:
        raws = [results[key].cameras[camera].raw for key in (True, "detector")]
        verified, detected = (raw.records for raw in raws)
        assert raws[0].markers_verified >= 0.5 * verified.in_region.sum() > 0, camera
        assert raws[1].markers_verified == 0, camera
        keys = [list(zip(r.pattern.tolist(), r.marker.tolist())) for r in (verified, detected)]
        assert set(keys[1]) <= set(keys[0]), camera
        first = [keys[0].index(k) for k in keys[1]]
        difference = np.linalg.norm(verified.centre[first] - detected.centre, axis=1)
        wide = detected.side_px >= MIN_SIDE_PX
        assert np.sqrt(np.mean(difference[wide] ** 2)) < MAX_VERIFIED_RMS_DIFFERENCE_PX, camera


def test_markers_verified_at_their_predictions_equal_detected_ones_aruco(aruco_results):
    check_verified_equals_detected(aruco_results)


def test_markers_verified_at_their_predictions_equal_detected_ones_apriltag(apriltag_results):
    check_verified_equals_detected(apriltag_results)


def test_detections_come_from_clean_frames_only(aruco, aruco_results):
    _, sequence, truth = aruco
    for camera, report in aruco_results[True].cameras.items():
        raw = report.raw
        clean = truth["clean_frames"][camera]
        records = raw.records
        for pattern, first, count in zip(records.pattern, records.first_frame, records.frame_count):
            assert set(range(first, first + count)) <= set(clean[pattern]), (camera, pattern)
        assert raw.patterns_dropped == 0
        # Frames between the codes that show no pattern to detect are never converted.
        assert raw.frames_converted < raw.frames_decoded
        assert raw.frames_detected <= len(sequence.patterns)


def test_the_thumbnail_shows_the_pattern_where_most_markers_were_found(aruco_results):
    """The report draws a camera's detections on it: the first pattern may show one
    marker to a zoomed camera where another shows tens."""
    for result in aruco_results.values():
        for name, camera in result.cameras.items():
            found = np.bincount(camera.raw.records.pattern)
            chosen = camera.raw.thumbnail_pattern
            assert found[chosen] == found.max(), name
            assert chosen == int(np.argmax(found)), name  # ties: the earlier pattern


def test_merged_centre_is_the_mean_of_the_kept_scales_moved_by_their_drift(aruco_results):
    result = aruco_results[True]
    options = IngestOptions()
    for camera, report in result.cameras.items():
        raw = report.raw
        records, centres = raw.records, raw.centres
        for array, marker, xy, drift in zip(centres.array, centres.marker, centres.xy, centres.drift):
            mine = (records.array == array) & (records.marker == marker)
            kept = mine & records.kept
            assert np.allclose(records.centre[kept].mean(axis=0) + drift, xy)
            assert np.all(records.deviation_px[kept] <= options.max_deviation_px)
            assert np.all(records.deviation_px[mine & ~records.kept] > options.max_deviation_px)


def merged_centre_rms(result, truth) -> dict[str, float]:
    """Each camera's root mean square error of its merged centres against the truth (px)."""
    return {name: float(np.sqrt(np.mean(centre_errors(result, truth, name)[0] ** 2))) for name in result.cameras}


def test_the_scales_drift_on_an_uneven_floor_is_taken_out(tmp_path):
    """On a floor 10 mm uneven (over 1.5 m), a marker's corners leave its plane and its
    centre drifts with the square of its size: the merged centres are off their truth by
    0.10-0.17 px. The drift measured from the scales of each MSM, smoothly over the floor,
    brings every camera's closer (measured: 0.159 -> 0.129, 0.101 -> 0.084, 0.173 ->
    0.131 px); on the flat floor of the same room no drift is found."""
    from calibproj.simulate.scene import FloorRelief

    sequence = msm_sequence("aruco:4X4_50")
    scene = load_scene("small", seed=7)
    scene = replace(scene, floor=replace(scene.floor, relief=FloorRelief(rms_m=0.01, wavelength_m=1.5)))
    simulate_videos(scene, sequence, tmp_path, seed=7)
    truth = json.loads((tmp_path / "truth.json").read_text())
    runs = {on: ingest(tmp_path / "videos", sequence, tmp_path / "intrinsics",
                       options=IngestOptions(explore_interval=0, scale_drift=on), progress=False)
            for on in (False, True)}
    before, after = merged_centre_rms(runs[False], truth), merged_centre_rms(runs[True], truth)
    for name, camera in runs[True].cameras.items():
        drift = camera.raw.scale_drift
        assert drift.bandwidth > 0.0 and drift.corrected == len(camera.raw.centres), name
        assert after[name] < 0.9 * before[name], (name, before[name], after[name])
        assert runs[True].report()["cameras"][name]["scale_drift"]["corrected"] == drift.corrected
        assert np.all(runs[False].cameras[name].raw.centres.drift == 0.0)


def test_no_drift_is_found_on_a_flat_floor(aruco, aruco_results):
    for name, camera in aruco_results[True].cameras.items():
        drift = camera.raw.scale_drift
        assert drift.msms >= 30, name
        assert drift.bandwidth == 0.0 and drift.corrected == 0, (name, drift.disagreement_none, drift.disagreement_chosen)
        assert np.all(camera.raw.centres.drift == 0.0)


def test_cameras_ingested_together_share_the_cores_for_decoding():
    shared = _core.ingest.shared_decode_threads
    cores = os.cpu_count() or 1
    assert shared(3, 8) == 3  # asked for: kept
    assert shared(0, 1) == max(1, cores - 1)  # one camera: a core left to its detection
    assert shared(0, cores) == 1
    assert shared(0, 4 * cores) == 1  # never none
    assert shared(0, 2) == max(1, cores // 2)


def test_the_decoding_threads_do_not_change_the_ingest(aruco):
    """One decoding thread per camera (as cameras ingested side by side get) decodes the
    same frames as FFmpeg's frame threads: the same sync and centres to the last bit."""
    out, sequence, _ = aruco
    results = [ingest(out / "videos", sequence, out / "intrinsics", options=IngestOptions(decode_threads=threads),
                      progress=False, workers=1) for threads in (1, 3)]
    for name, camera in results[0].cameras.items():
        other = results[1].cameras[name].raw
        assert camera.raw.sync.map.offset == other.sync.map.offset, name
        assert np.array_equal(camera.raw.signal, other.signal, equal_nan=True), name
        np.testing.assert_array_equal(camera.raw.centres.xy, other.centres.xy)
        assert len(camera.raw.centres.xy) > 0


def test_averaged_frames_stay_accurate(aruco):
    out, sequence, truth = aruco
    result = ingest(out / "videos", sequence, out / "intrinsics", options=IngestOptions(average_frames=3),
                    progress=False)
    counts = np.concatenate([c.raw.records.frame_count for c in result.cameras.values()])
    # As many as the camera records clean, up to three (the test room shows each pattern
    # for only 3 projector frames).
    assert 1 < counts.max() <= 3
    check_accuracy({True: result}, truth)


def test_scales_a_camera_cannot_resolve_are_skipped(aruco, aruco_results):
    out, sequence, _ = aruco
    coarse = ingest(out / "videos", sequence, out / "intrinsics", options=IngestOptions(min_module_px=4.5),
                    progress=False)
    for camera, report in coarse.cameras.items():
        smallest = report.raw.scales[0]
        assert smallest.skipped_patterns > 0, camera
        assert report.raw.frames_detected < aruco_results[True].cameras[camera].raw.frames_detected


def test_a_recording_that_runs_on_is_not_decoded_past_the_projection(aruco, aruco_results, tmp_path):
    """The same room recorded 4 s longer: decoding stops after the end code's window and
    the last pick, and the observations are those of the short recording."""
    from calibproj.simulate.render import RenderOptions

    _, sequence, _ = aruco
    simulate_videos("small", sequence, tmp_path, seed=7, options=RenderOptions(tail_s=4.0))
    truth = json.loads((tmp_path / "truth.json").read_text())
    result = ingest(tmp_path / "videos", sequence, tmp_path / "intrinsics",
                    options=IngestOptions(explore_interval=0), progress=False)
    short = aruco_results[True]
    for name, camera in result.cameras.items():
        timing = truth["timing"]["cameras"][name]
        assert camera.raw.frames_decoded < timing["recorded_frames"] - 3.5 * timing["fps"], name
        ids, xy = result.tracks.observations(name)
        short_ids, short_xy = short.tracks.observations(name)
        np.testing.assert_array_equal(ids, short_ids)
        np.testing.assert_allclose(xy, short_xy, atol=1e-9)


def test_detect_command_writes_tracks_and_report(aruco, tmp_path, capsys):
    out, sequence, _ = aruco
    sequence_file = tmp_path / "sequence.json"
    sequence.save(sequence_file)
    tracks_file = tmp_path / "results" / "tracks.json"
    status = main(["detect", str(out / "videos"), "--sequence", str(sequence_file), "--intrinsics",
                   str(out / "intrinsics"), "--out", str(tracks_file), "--no-progress"])
    assert status == 0
    tracks = Tracks.read(tracks_file)
    assert tracks.camera_names == ("cam1", "cam2", "cam3")
    assert tracks.markers_per_array == 32
    report = json.loads((tracks_file.parent / "detect_report.json").read_text())
    assert report["schema"] == "calibproj.detect_report/1"
    for name in tracks.camera_names:
        camera = report["cameras"][name]
        assert camera["status"] == "ok"
        assert set(camera["sync"]) >= {"offset_s", "offset_frames", "rate", "camera_fps", "drift_ppm"}
        assert camera["msms_kept"] == tracks.counts_per_camera()[name]
        assert [s["scale"] for s in camera["scales"]] == [1.0, 2.0, 3.0]
        assert camera["frames"]["detected"] > 0
    printed = capsys.readouterr().out
    assert "cam2: offset" in printed and "markers found/searched per scale" in printed


@pytest.mark.parametrize("flag,value,message", [
    ("--decode-threads", "-1", "decode_threads must be in [0, 256]"),
    ("--detection-threads", "0", "detection_threads must be in [1, 256]")])
def test_a_bad_ingest_option_stops_the_command_before_any_camera(aruco, tmp_path, capsys, flag, value, message):
    """Found by probing: a bad value failed every camera on its own (one line each) and
    still wrote a tracks file without cameras; calibproj-native refused it up front."""
    out, sequence, _ = aruco
    sequence_file = tmp_path / "sequence.json"
    sequence.save(sequence_file)
    tracks_file = tmp_path / "results" / "tracks.json"
    status = main(["detect", str(out / "videos"), "--sequence", str(sequence_file), "--intrinsics",
                   str(out / "intrinsics"), "--out", str(tracks_file), "--no-progress", flag, value])
    captured = capsys.readouterr()
    assert status != 0 and not tracks_file.exists()
    assert captured.err.strip() == f"calibproj detect: error: ingest options: {message}"
    assert "FAILED" not in captured.out


# ------------------------------------------------------- corners under distortion

# A GoPro-like wide-angle lens on a 960 x 540 image.
WIDE = Intrinsics("wide", (960, 540), np.array([[460.0, 0, 479.5], [0, 460.3, 269.5], [0, 0, 1]]),
                  np.array([-0.26, 0.09, 0.0003, -0.0002, -0.012]))


def distorted_marker(centre: np.ndarray, module_px: float) -> np.ndarray:
    """A white-on-black marker whose undistorted centre is `centre`, seen through WIDE."""
    import cv2

    offset = np.array([720.0, 430.0])  # the undistorted plane of the image, shifted to fit a canvas
    canvas = np.zeros((1400, 2400), np.float32)
    marker = render_marker("aruco:4X4_50", 3, module_px=module_px, inverted=True).astype(np.float32)
    top_left = centre + offset - (np.array(marker.shape[::-1]) - 1) / 2
    x0, y0 = np.floor(top_left).astype(int)
    fraction = top_left - (x0, y0)
    marker = cv2.warpAffine(marker, np.float32([[1, 0, fraction[0]], [0, 1, fraction[1]]]),
                            (marker.shape[1] + 2, marker.shape[0] + 2))
    canvas[y0:y0 + marker.shape[0], x0:x0 + marker.shape[1]] = marker
    pixels = np.stack(np.meshgrid(np.arange(960.0), np.arange(540.0)), -1).reshape(-1, 2)
    source = (WIDE.undistort_points(pixels) + offset).reshape(540, 960, 2).astype(np.float32)
    image = cv2.GaussianBlur(cv2.remap(canvas, source[..., 0], source[..., 1], cv2.INTER_LINEAR), (0, 0), 0.7)
    return np.clip(0.8 * image + 30, 0, 255).astype(np.uint8)


def test_edges_fitted_in_undistorted_pixels_keep_large_markers_exact():
    """Near the corners of a wide-angle image the edges of a large marker bend: corners
    refined in the image and then undistorted put its centre off by most of a pixel;
    straight edges fitted in undistorted pixels do not."""
    raw_detector = MarkerDetector("aruco:4X4_50", inverted=True, corner_refinement="none")
    image_detector = MarkerDetector("aruco:4X4_50", inverted=True)
    for centre, module in ((np.array([150.0, 120.0]), 22.0), (np.array([800.0, 420.0]), 16.0)):
        image = distorted_marker(centre, module)
        _, raw = raw_detector.detect(image)
        _, refined_in_image = image_detector.detect(image)
        ours = _core.ingest.refine_undistorted_corners(image, raw[0], WIDE, 6)
        error = np.linalg.norm(marker_centres(ours[None])[0] - centre)
        naive = np.linalg.norm(marker_centres(WIDE.undistort_points(refined_in_image[0])[None])[0] - centre)
        assert error < 0.03 and naive > 0.3, (centre, error, naive)


def test_a_marker_is_verified_only_where_and_as_it_is_drawn():
    """The check that accepts a marker at its predicted corners: the right id on its
    refined corners passes; another id, the other polarity or corners one module off do
    not."""
    raw_detector = MarkerDetector("aruco:4X4_50", inverted=True, corner_refinement="none")
    image = distorted_marker(np.array([800.0, 420.0]), 16.0)
    _, raw = raw_detector.detect(image)
    corners = _core.ingest.refine_undistorted_corners(image, raw[0], WIDE, 6)
    verify = partial(_core.ingest.shows_marker, image, intrinsics=WIDE, spec="aruco:4X4_50")
    assert verify(corners, id=3, inverted=True)
    assert not verify(corners, id=4, inverted=True)
    assert not verify(corners, id=3, inverted=False)
    module = (corners[1] - corners[0]) / 6
    assert not verify(corners + module, id=3, inverted=True)


def test_lens_tables_match_the_exact_mapping():
    """Inside the image and in the margin around it, even beyond the radius where the
    wide-angle model folds back (where the exact function's answer is kept)."""
    rng = np.random.default_rng(0)
    pixels = rng.uniform([-60, -60], [1019, 599], (4000, 2))
    undistorted = _core.ingest.lens_tables_map(WIDE, (960, 540), pixels, True)
    exact = WIDE.undistort_points(pixels)
    folded = np.abs(WIDE.distort_points(exact) - pixels).max(axis=1) > 1e-6
    assert 0 < folded.sum() < 0.1 * len(pixels)
    assert np.abs(undistorted - exact).max() < 1e-4
    distorted = _core.ingest.lens_tables_map(WIDE, (960, 540), undistorted, False)
    assert np.abs(distorted - WIDE.distort_points(undistorted)).max() < 1e-9


# -------------------------------------------------------------------- failures

def failing_setup(aruco, apriltag, folder: Path) -> dict[str, str]:
    """A videos and an intrinsics folder where cam1 is fine and every other camera is
    broken in its own way; returns the file each error must name."""
    out, _, _ = aruco
    other, _, _ = apriltag
    videos, intrinsics = folder / "videos", folder / "intrinsics"
    videos.mkdir()
    intrinsics.mkdir()
    good = out / "videos" / "cam1.mp4"
    shutil.copy(good, videos / "cam1.mp4")
    data = good.read_bytes()
    (videos / "corrupt.mp4").write_bytes(bytes(reversed(data[:20000])))
    (videos / "halfbytes.mp4").write_bytes(data[: len(data) // 2])
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-i", str(good), "-frames:v", "100", "-c", "copy",
                    str(videos / "cut.mp4")], check=True)
    shutil.copy(other / "videos" / "cam1.mp4", videos / "other.mp4")
    shutil.copy(good, videos / "nointrinsics.mp4")
    shutil.copy(good, videos / "wrongsize.mp4")
    cam1 = read_intrinsics(out / "intrinsics" / "cam1.json")
    for name in ("cam1", "corrupt", "halfbytes", "cut", "other", "wrongsize"):
        write_intrinsics(intrinsics / f"{name}.json", cam1)
    wrong = read_intrinsics(out / "intrinsics" / "cam1.json")
    text = json.loads((intrinsics / "wrongsize.json").read_text())
    text["resolution"] = [wrong.resolution[0] * 2, wrong.resolution[1] * 2]
    (intrinsics / "wrongsize.json").write_text(json.dumps(text))
    return {
        "corrupt": str(videos / "corrupt.mp4"),
        "halfbytes": str(videos / "halfbytes.mp4"),
        "cut": str(videos / "cut.mp4"),
        "other": str(videos / "other.mp4"),
        "nointrinsics": str(intrinsics / "nointrinsics.json"),
        "wrongsize": str(videos / "wrongsize.mp4"),
    }


def test_failing_cameras_are_reported_and_the_others_give_tracks(aruco, apriltag, tmp_path):
    expected = failing_setup(aruco, apriltag, tmp_path)
    _, sequence, _ = aruco
    result = ingest(tmp_path / "videos", sequence, tmp_path / "intrinsics", progress=False)
    assert set(result.failed) == set(expected)
    for name, path in expected.items():
        assert path in result.failed[name], (name, result.failed[name])
    assert "cannot open" in result.failed["corrupt"]
    assert "end light code not found" in result.failed["cut"]
    assert "another sequence" in result.failed["other"]
    assert "no intrinsics file" in result.failed["nointrinsics"]
    assert "640x360" in result.failed["wrongsize"] and "1280x720" in result.failed["wrongsize"]
    assert result.tracks.counts_per_camera()["cam1"] > 30
    assert set(result.tracks.camera_names) == set(expected) | {"cam1"}
    report = result.report()["cameras"]
    assert report["cam1"]["status"] == "ok"
    assert all(report[name]["status"] == "failed" for name in expected)
    # The camera whose end code is cut off carries its brightness trace for the report
    # (a flickering start code in it); a camera that failed otherwise does not.
    trace = report["cut"]["brightness"]
    values = np.asarray(trace["values"], dtype=float)
    assert trace["frames_per_value"] >= 1 and len(values) > 20 and np.nanstd(values) > 0.05
    assert "brightness" not in report["corrupt"] and "brightness" not in report["wrongsize"]
    # Each camera that decoded a frame has its thumbnail, of the configured width.
    assert result.cameras["cam1"].thumbnail().shape[1] == 640
    assert result.cameras["cut"].thumbnail() is None


def test_a_failed_sync_is_drawn_in_the_report(tmp_path) -> None:
    from calibproj.report.page import sync_plots

    values = [0.1] * 40 + [0.1, 0.9] * 20 + [0.5] * 100
    report = {"cameras": {"cut": {"status": "failed", "error": "cut.mp4: end light code not found",
                                  "brightness": {"frames_per_value": 2, "values": values}},
                          "bad": {"status": "failed", "error": "x", "brightness": {"values": "nonsense"}}}}
    plots = sync_plots(report, dpi=40)
    assert [plot.file_name for plot in plots] == ["sync_cut.png"]
    assert plots[0].png.startswith(b"\x89PNG")


def test_an_interrupted_ingest_stops_every_camera_early(aruco, monkeypatch):
    """Ctrl-C while the cameras decode: the KeyboardInterrupt reaches the caller, and
    every camera's C++ ingest stops at its next progress call instead of decoding its
    video to the end (the worker threads used to run on for seconds)."""
    import signal
    import threading

    import calibproj.ingest.videos as ingest_module

    out, sequence, _ = aruco
    first_call = threading.Event()
    seen: dict[str, list[tuple[int, int]]] = {}
    original = ingest_module._Progress.callback

    def callback(self, name):
        inner = original(self, name)

        def update(decoded: int, total: int) -> None:
            seen.setdefault(name, []).append((decoded, total))
            first_call.set()
            # No camera gets further before the key is pressed, however fast it decodes.
            pressed.wait(10)
            inner(decoded, total)

        return update

    monkeypatch.setattr(ingest_module._Progress, "callback", callback)
    pressed = threading.Event()

    def press_ctrl_c() -> None:  # a real SIGINT to the main thread, as a terminal sends it
        if first_call.wait(120):
            signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)
            pressed.set()

    # Python as a terminal starts it (a job started in the background ignores SIGINT).
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        threading.Thread(target=press_ctrl_c, daemon=True).start()
        with pytest.raises(KeyboardInterrupt):
            ingest(out / "videos", sequence, out / "intrinsics", progress=False, workers=2)
    finally:
        signal.signal(signal.SIGINT, previous)
    # A worker the pool was starting when the key came is not among those it joins: it
    # finds its camera cancelled and ends at once.
    def workers() -> list[threading.Thread]:
        return [t for t in threading.enumerate() if t.name.startswith("ingest")]

    deadline = time.monotonic() + 2.0
    while workers() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert seen and not workers()
    for name, calls in seen.items():
        decoded, total = calls[-1]
        assert total > 0 and decoded < total / 2, (name, calls)


def with_static_markers(video: Path, out: Path, ids: tuple[int, ...], markers: str, side_px: float) -> None:
    """The video again, with markers of the family pasted in every frame along its
    bottom edge: a floor marking that decodes, as the projection's markers look."""
    capture = cv2.VideoCapture(str(video))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY))
    height, width = frames[0].shape
    stamps = []
    for k, marker_id in enumerate(ids):
        stamp = render_marker(markers, marker_id, module_px=side_px / 6.0, inverted=True)
        x = 10 + k * (stamp.shape[1] + 10)
        stamps.append((stamp, slice(height - 10 - stamp.shape[0], height - 10), slice(x, x + stamp.shape[1])))
    with GreyVideoWriter(out, (width, height), _core.video.probe(str(video)).fps, crf=0,
                         preset="ultrafast", timestamps_s=_core.video.frame_timestamps(str(video))) as writer:
        for frame in frames:
            for stamp, rows, columns in stamps:
                frame[rows, columns] = stamp
            writer.write(frame)


def test_a_marking_that_decodes_does_not_shrink_the_search_below_the_real_markers(tmp_path):
    """Before the homography, whole frames are shrunk as far as the markers found so far
    allow. Two large static markings that decode as the projection's markers (90 px,
    where the first pattern's real markers are too small to see) once taught it a
    magnification 7x too large, and every later frame was shrunk until no real marker
    survived (0 MSMs). They now cost the camera no more than markings with ids the
    projection does not show, which only hide what they cover."""
    sequence = build_sequence(markers="aruco:4X4_50", arrays=3, scales=(0.25, 2.0, 3.0), marker_px=48.0,
                              code_degree=4, reference_frames=8)
    small = load_scene("small", seed=7)
    room = tmp_path / "room"
    simulate_videos(replace(small, cameras=small.cameras[:1]), sequence, room, seed=7)
    name = small.cameras[0].name
    kept = {}
    for ids in ((40, 41), (0, 1)):  # the arrays show ids 0-31
        folder = tmp_path / f"marked-{ids[0]}"
        folder.mkdir()
        with_static_markers(room / "videos" / f"{name}.mp4", folder / f"{name}.mp4", ids=ids,
                            markers="aruco:4X4_50", side_px=90.0)
        result = ingest(folder, sequence, room / "intrinsics", options=IngestOptions(explore_interval=0),
                        progress=False)
        assert not result.failed
        kept[ids] = result.cameras[name].summary()["msms_kept"]
    assert kept[40, 41] >= 40 and kept[0, 1] >= 0.9 * kept[40, 41], kept
