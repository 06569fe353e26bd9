"""Targeted densification (calibproj.sequence.densify) and merged calibration, on the
demo room with a sparse first projection: the zoomed ceiling camera sees a handful of
centres and is weak; the extra projection planned from that first calibration fills
its view, and the merged calibration knows it as well as the others, within its sigma."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from calibproj.evaluation.comparison import CameraPoses, compare
from calibproj.pipeline import calibrate
from calibproj.sequence import Sequence, build_sequence
from calibproj.sequence.densify import DensifyOptions, densify
from calibproj.simulate import simulate_tracks
from calibproj.simulate.geometric import project_points, projected_points
from calibproj.simulate.scene import load_scene
from calibproj.formats.tracks import Tracks

from test_native import run_native


def truth_poses(scene) -> CameraPoses:
    return CameraPoses({camera.name: (camera.R, camera.t) for camera in scene.cameras}, "m")


def ceiling_error_deg(calibration, scene) -> float:
    poses = CameraPoses(calibration.poses, calibration.unit, calibration.failed)
    return compare(poses, truth_poses(scene)).cameras["ceiling"].rotation_deg


@pytest.fixture(scope="module")
def room(tmp_path_factory) -> dict:
    """The demo room, a 12-array first projection calibrated, and its densified sequence."""
    folder = tmp_path_factory.mktemp("densify")
    scene = load_scene("demo")
    sequence = build_sequence(arrays=12, scales=(1.0, 3.0, 6.0))
    first = simulate_tracks(scene, folder / "first", noise_px=0.1, seed=21, layout=sequence)
    sequence.save(folder / "sequence.json")
    calibration = calibrate(first.tracks, first.intrinsics, sequence=folder / "sequence.json",
                            out=folder / "results", report=False)
    dense, plans = densify(folder / "results", sequence)
    return {"folder": folder, "scene": scene, "sequence": sequence, "first": first, "calibration": calibration,
            "dense": dense, "plans": plans}


def test_the_first_projection_leaves_the_zoomed_camera_weak(room) -> None:
    metrics = room["calibration"].metrics["ceiling"]
    assert "ceiling" in room["calibration"].registered and metrics.weak
    assert metrics.inliers < 15
    assert [plan.footprint.camera for plan in room["plans"]] == ["ceiling"]


def test_the_plan_fills_the_camera_view_with_markers_sized_for_it(room) -> None:
    scene, dense, (plan,) = room["scene"], room["dense"], room["plans"]
    camera = next(c for c in scene.cameras if c.name == "ceiling")
    width, height = camera.resolution
    new = np.concatenate(plan.centres)
    assert len(new) >= 100
    # Every planned centre lands, in truth, inside the camera's image.
    floor, _ = projected_points(scene, new)
    pixels = project_points(camera, floor, 0.1).distorted
    assert np.all((pixels >= 0) & (pixels <= [width, height]))
    # The marker sides, in the camera's pixels (truth: a marker's floor corners
    # projected), span the planned range of its image's shorter side.
    options = DensifyOptions()
    for side, bound in ((plan.sides_px[0], options.min_side_fraction), (plan.sides_px[-1], options.max_side_fraction)):
        corners = projected_points(scene, new[:1] + 0.5 * side * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]))[0]
        image = project_points(camera, corners, 0.1).distorted
        diagonal, other = image[2] - image[0], image[3] - image[1]
        seen = np.sqrt(0.5 * abs(diagonal[0] * other[1] - diagonal[1] * other[0]))  # the square's area
        assert seen == pytest.approx(bound * min(width, height), rel=0.3)
    # Markers of one extra array keep min_gap_modules of the largest marker between
    # them: an oblique camera sees them small, and closer ones blur into each other.
    module = plan.sides_px[-1] / room["sequence"].markers.grid_cells
    for centres in plan.centres:
        apart = np.abs(centres[:, None, :] - centres[None, :, :]).max(axis=-1)
        np.fill_diagonal(apart, np.inf)
        assert apart.min() >= plan.sides_px[-1] + options.min_gap_modules * module - 1e-6


def test_the_densified_sequence_keeps_the_first_arrays_and_shows_only_new_ones(room, tmp_path) -> None:
    sequence, dense = room["sequence"], room["dense"]
    arrays = sequence.layout.arrays
    np.testing.assert_array_equal(dense.centres[:arrays], sequence.centres)
    assert min(pattern.array for pattern in dense.patterns) == arrays
    assert dense.duration_s <= DensifyOptions().max_seconds
    dense.save(tmp_path / "sequence.json")
    again = Sequence.load(tmp_path / "sequence.json")
    np.testing.assert_array_equal(again.centres, dense.centres)
    assert len(again.patterns) == len(dense.patterns)


@pytest.fixture(scope="module")
def merged(room) -> dict:
    """The densified projection simulated and calibrated with the first one's observations."""
    folder = room["folder"]
    room["dense"].save(folder / "dense.json")
    extra = simulate_tracks(room["scene"], folder / "dense", noise_px=0.1, seed=121, layout=room["dense"])
    calibration = calibrate(folder / "dense" / "tracks.json", folder / "results" / "intrinsics",
                            sequence=folder / "dense.json", merge=folder / "results", out=folder / "merged",
                            report=False)
    return {"extra": extra, "calibration": calibration}


def test_the_merged_calibration_knows_the_zoomed_camera_within_its_sigma(room, merged) -> None:
    folder, scene, extra, merged = room["folder"], room["scene"], merged["extra"], merged["calibration"]
    assert extra.tracks.point_ids.min() >= room["sequence"].point_count
    before, after = room["calibration"].metrics["ceiling"], merged.metrics["ceiling"]
    assert not after.weak and after.inliers > 5 * before.inliers
    # Over ten seeds of both projections the error relative to the reference camera is
    # sqrt(3) = 1.73 times the largest axis sigma (RMS; 1.70 measured), as an honest
    # sigma of a rotation (three axes) gives: 3 sigma holds in about 97 % of rooms.
    error = ceiling_error_deg(merged, scene)
    assert error <= 3.0 * after.rotation_sigma_deg
    assert error < ceiling_error_deg(room["calibration"], scene)
    assert after.rotation_sigma_deg < 0.5 * before.rotation_sigma_deg
    stored = Tracks.read(folder / "merged" / "tracks.json")
    assert len(stored) == len(Tracks.read(folder / "results" / "tracks.json")) + len(extra.tracks)
    provenance = json.loads((folder / "merged" / "provenance.json").read_text())
    assert provenance["inputs"]["merged"]["path"].endswith("results")
    # calibproj-native merges to the same bytes.
    native = run_native("calibrate", "--tracks", str(folder / "dense" / "tracks.json"), "--merge",
                        str(folder / "results"), "--sequence", str(folder / "dense.json"), "--intrinsics",
                        str(folder / "results" / "intrinsics"), "--out", str(folder / "native"))
    assert native.returncode == 0, native.stderr
    for name in ("points.ply", "tracks.json"):
        assert (folder / "native" / name).read_bytes() == (folder / "merged" / name).read_bytes(), name
    # The covariance's last bits depend on what ran before in the same process (a sparse
    # QR's sums), so the sigmas are compared to 1e-9, everything else exactly.
    for name in ("camera_poses.json", "metrics.json"):
        native_doc = json.loads((folder / "native" / name).read_text())
        python_doc = json.loads((folder / "merged" / name).read_text())
        assert_same_document(native_doc, python_doc, name)


def test_a_texture_that_moves_large_markers_more_leaves_the_small_ones_their_weight(room) -> None:
    """A floor texture moves a marker's apparent centre on the floor, the same way for
    every camera, by a share of the marker's size. Simulated: every MSM centre moved by
    0.2 % of the side of its largest marker (rms per axis, projector px), 0.29 px for the
    first projection's markers, 0.07 px for the extra projection's small ones. The
    registration estimates the projector's noise per marker size, and the zoomed camera,
    whose points the small markers tie to the projector, keeps their weight."""

    from calibproj.evaluation.comparison import rotation_errors_to_reference
    from calibproj.registration.driver import RegistrationDriver, RegistrationOptions
    from calibproj.sequence.projected import ProjectedMarkers, projected_markers

    scene, sequence, dense, intrinsics = room["scene"], room["sequence"], room["dense"], room["first"].intrinsics
    rng = np.random.default_rng(0)

    def displaced(seq):
        sides = np.nan_to_num(projected_markers(seq).largest_side_px)
        return seq.replaced(centres=seq.centres + rng.normal(size=seq.centres.shape) * 0.002 * sides[..., None])

    first = simulate_tracks(scene, None, noise_px=0.05, seed=31, layout=displaced(sequence)).tracks
    extra = simulate_tracks(scene, None, noise_px=0.05, seed=131, layout=displaced(dense)).tracks
    tracks = Tracks.from_observations(
        first.camera_names, np.concatenate([first.camera_index, [first.camera_names.index(extra.camera_names[c])
                                                                  for c in extra.camera_index]]),
        np.concatenate([first.point_ids[first.point_index], extra.point_ids[extra.point_index]]),
        np.concatenate([first.xy, extra.xy]), first.markers_per_array)
    by_size = projected_markers(dense)
    # The densified sequence draws only the new arrays: the first ones' sides are not known.
    sides = np.unique(by_size.largest_side_px[~np.isnan(by_size.largest_side_px)])
    assert len(sides) == 1 and np.all(np.isnan(by_size.largest_side_px[:sequence.layout.arrays]))
    # Independent simulated errors on an exactly flat floor (what the relief would take up
    # of the displaced centres is not what this test is about).
    options = RegistrationOptions(error_correlation=0.0, shared_error_shift=0.0, shared_error_field=0.0,
                                  floor_relief=0.0)
    sigma = {}
    for name, markers in (("one noise", ProjectedMarkers(by_size.centres_px, by_size.marker_side_px, by_size.projector)), ("by size", by_size)):
        driver = RegistrationDriver(tracks, intrinsics, options, projector=markers)
        calibration = driver.run()
        sigma[name] = calibration.metrics["ceiling"].rotation_sigma_deg
        reference = next(n for n in calibration.poses if calibration.metrics[n].rotation_sigma_deg == 0.0)
        error = rotation_errors_to_reference(calibration.poses, reference, {c.name: c.R for c in scene.cameras})
        assert error["ceiling"] <= 3.0 * sigma[name], name
    groups = dict(zip(driver.reconstruction.projector_group_sides_px, driver.reconstruction.projector_sigma_px))
    assert len(groups) == 2
    first_sigma = next(value for side, value in groups.items() if np.isnan(side))
    assert first_sigma == pytest.approx(0.002 * sequence.layout.marker_side(6.0), rel=0.2)
    assert groups[sides[0]] == pytest.approx(0.002 * sides[0], rel=0.2)
    assert sigma["by size"] < 0.85 * sigma["one noise"]


def test_a_camera_that_sees_few_msms_at_two_scales_keeps_its_centres(room, tmp_path) -> None:
    """The extra projection's markers are sized for the zoomed camera: the near camera
    sharing its patch sees most of them at one scale. On a floor 6 mm uneven it keeps
    11 MSMs at two scales, too few to measure the scales' drift: with 8 allowed, noise
    passed for a drift, moved its 210 centres and left them farther from the truth (in
    the rendered demo room the zoomed camera sharing them turned 0.17 deg, 5.4 sigma)."""
    from dataclasses import replace

    from calibproj.ingest.options import IngestOptions
    from calibproj.ingest.videos import ingest
    from calibproj.simulate.render import simulate_videos
    from calibproj.simulate.scene import FloorRelief

    scene = room["scene"]
    uneven = replace(scene, floor=replace(scene.floor, relief=FloorRelief(rms_m=0.006, seed=2)),
                     cameras=[camera for camera in scene.cameras if camera.name == "near1"])
    simulate_videos(uneven, room["dense"], tmp_path, seed=1)
    truth = json.loads((tmp_path / "truth.json").read_text())["image_points"]["near1"]
    true_xy = dict(zip(truth["ids"], truth["undistorted"]))

    def ingested(options: IngestOptions):
        result = ingest(tmp_path / "videos", room["dense"], tmp_path / "intrinsics", options=options, progress=False)
        ids, xy = result.tracks.observations("near1")
        errors = np.array([np.asarray(observed) - true_xy[int(point)] for point, observed in zip(ids, xy)])
        return result.cameras["near1"].raw, float(np.sqrt(np.mean(errors ** 2)))

    (kept, kept_rms), (moved, moved_rms) = ingested(IngestOptions()), ingested(IngestOptions(scale_drift_min_msms=8))
    assert 8 <= kept.scale_drift.msms < IngestOptions().scale_drift_min_msms
    assert kept.scale_drift.corrected == 0 and np.all(kept.centres.drift == 0.0)
    assert moved.scale_drift.corrected == len(moved.centres) > 100
    assert moved_rms > 1.1 * kept_rms, (kept_rms, moved_rms)


def assert_same_document(a, b, where: str) -> None:
    """Equal JSON documents, floats to 1e-9 (relative) where their key names a sigma."""
    assert type(a) is type(b), where
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for key in a:
            assert_same_document(a[key], b[key], f"{where}/{key}")
    elif isinstance(a, list):
        assert len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b)):
            assert_same_document(x, y, f"{where}/{k}")
    elif isinstance(a, float) and "sigma" in where.rsplit("/", 1)[-1]:
        assert a == pytest.approx(b, rel=1e-9), where
    else:
        assert a == b, where


def run_python(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "calibproj", *args], capture_output=True, text=True)


def test_generate_densify_writes_the_sequence_and_says_what_it_adds(room, merged, tmp_path) -> None:
    folder = room["folder"]
    result = run_python("generate", "--densify", str(folder / "results"), "--no-video", "--out", str(tmp_path / "d"),
                        "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["cameras"]["ceiling"]["centres"] >= 100
    assert 0 < summary["extra_seconds"] <= 15.0
    assert Sequence.load(tmp_path / "d" / "sequence.json").layout.arrays > room["sequence"].layout.arrays
    # Once merged no camera is weak or short of points: nothing to plan, nothing written.
    result = run_python("generate", "--densify", str(folder / "merged"), "--sequence", str(folder / "dense.json"),
                        "--no-video", "--out", str(tmp_path / "none"))
    assert result.returncode == 0 and "no camera needs densification" in result.stdout
    assert not (tmp_path / "none").exists()


@pytest.mark.parametrize("case", ["same ids", "other intrinsics", "no tracks", "unknown camera", "too short"])
def test_bad_merges_and_plans_give_one_clear_line(room, tmp_path, case: str) -> None:
    folder = room["folder"]
    results = str(folder / "results")
    intrinsics = folder / "results" / "intrinsics"
    if case == "same ids":  # the first projection's tracks merged with themselves
        args = ["calibrate", "--tracks", str(folder / "results" / "tracks.json"), "--merge", results,
                "--intrinsics", str(intrinsics), "--out", str(tmp_path / "r")]
        expected = "point id(s) in both"
    elif case == "other intrinsics":
        other = tmp_path / "intrinsics"
        other.mkdir()
        for path in intrinsics.iterdir():
            document = json.loads(path.read_text())
            document["K"][0][0] *= 1.001
            (other / path.name).write_text(json.dumps(document))
        args = ["calibrate", "--tracks", str(folder / "results" / "tracks.json"), "--merge", results,
                "--intrinsics", str(other), "--out", str(tmp_path / "r")]
        expected = "other intrinsics"
    elif case == "no tracks":
        (tmp_path / "empty").mkdir()
        args = ["calibrate", "--tracks", str(folder / "results" / "tracks.json"), "--merge", str(tmp_path / "empty"),
                "--intrinsics", str(intrinsics), "--out", str(tmp_path / "r")]
        expected = "tracks.json"
    elif case == "unknown camera":
        args = ["generate", "--densify", results, "--densify-cameras", "nobody", "--no-video",
                "--out", str(tmp_path / "d")]
        expected = "nobody"
    else:
        args = ["generate", "--densify", results, "--densify-seconds", "3", "--no-video", "--out", str(tmp_path / "d")]
        expected = "light codes"
    result = run_python(*args)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and expected in lines[0] and "Traceback" not in result.stderr
    assert not (tmp_path / "r").exists() and not (tmp_path / "d").exists()
    if args[0] == "calibrate":  # the same line from calibproj-native
        native = run_native(*args)
        assert native.returncode == 2 and expected in native.stderr, native.stderr
