"""Rendered simulation: geometry to the sub-pixel, frame rates and start offsets in the
decoded videos, exposure blending, outputs and bad inputs."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import cv2
import numpy as np
import pytest
from scipy.ndimage import map_coordinates

from calibproj.cli.main import main
from calibproj.sequence.builder import build_sequence
from calibproj.formats.intrinsics import read_intrinsics
from calibproj.formats.poses import read_poses
from calibproj.formats.tracks import Tracks
from calibproj.sequence.markers import MarkerDetector, marker_centres
from calibproj.simulate.atlas import AtlasLayout
from calibproj.simulate.geometric import project_points
from calibproj.simulate.render import IDEAL_PHOTOMETRIC, RenderOptions, render_stills, simulate_videos
from calibproj.simulate.scene import load_scene, save_scene
from calibproj.simulate.timeline import ProjectionTimeline
from calibproj.simulate.warp import floor_view

# Markers whose detected side is shorter than this are left out of the accuracy
# check: below it the detector's own error (not the renderer's) dominates.
MIN_CHECKED_SIDE_PX = 25.0


def short_sequence(**overrides):
    """Two arrays of 2 x 4 markers at two large scales, short codes: 72 projector frames."""
    options = {"arrays": 2, "scales": (6.0, 10.0), "grid": (2, 4), "code_degree": 3, "reference_frames": 3}
    return build_sequence(**{**options, **overrides})


def varied_scene():
    """The small preset with every frame rate that must work, short start offsets and
    no photometric effects; cam2 exposes for a whole frame, so every content change
    falls inside one of its frames."""
    small = load_scene("small")
    cam1, cam2, cam3 = small.cameras
    low_res = {"resolution": (320, 180), "fx": 152.5, "fy": 152.5, "cx": 159.5, "cy": 89.5}
    cameras = (
        replace(cam1, start_offset_s=0.31),
        replace(cam2, start_offset_s=0.43, exposure_s=0.04),
        replace(cam3, start_offset_s=0.62),
        replace(cam1, name="fast60", fps=60.0, start_offset_s=0.117, exposure_s=1 / 120),
        replace(cam3, name="fast240", fps=240.0, start_offset_s=0.0513, exposure_s=1 / 480, **low_res),
    )
    return replace(small, cameras=cameras, photometric=IDEAL_PHOTOMETRIC)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    out = tmp_path_factory.mktemp("render")
    sequence = short_sequence()
    simulation = simulate_videos(varied_scene(), sequence, out, seed=3)
    truth = json.loads((out / "truth.json").read_text())
    return simulation, sequence, truth


def read_frames(path) -> list[np.ndarray]:
    capture = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, image = capture.read()
        if not ok:
            return frames
        frames.append(image[:, :, 0])


def test_outputs_are_complete(rendered):
    simulation, _, truth = rendered
    out = simulation.out
    names = simulation.scene.camera_names
    assert sorted(p.stem for p in (out / "videos").glob("*.mp4")) == sorted(names)
    assert sorted(p.stem for p in (out / "intrinsics").glob("*.json")) == sorted(names)
    assert (out / "scene.json").is_file()
    evaluation = Tracks.read(out / "eval_tracks.json")
    assert list(evaluation.camera_names) == list(names)
    assert all(count > 0 for count in evaluation.counts_per_camera().values())
    assert read_poses(out / "truth.json").names == names
    assert truth["timing"]["projector_fps"] == 30.0
    assert set(truth["image_points"]) == set(names) == set(truth["clean_frames"])


def test_msm_centres_are_where_truth_says(rendered):
    """Markers detected in clean frames of the decoded (H.264, crf 18) videos, their
    corners undistorted, centres as diagonal intersections, against truth.json."""
    simulation, sequence, truth = rendered
    detector = MarkerDetector(sequence.markers.spec, inverted=sequence.markers.inverted)
    markers_per_array = truth["points"]["markers_per_array"]
    errors = []
    for name in ("cam1", "cam2", "cam3"):
        intrinsics = read_intrinsics(simulation.out / "intrinsics" / f"{name}.json")
        points = truth["image_points"][name]
        true_centres = dict(zip(points["ids"], np.array(points["undistorted"])))
        frames = read_frames(simulation.out / "videos" / f"{name}.mp4")
        for pattern, clean in zip(sequence.patterns, truth["clean_frames"][name]):
            ids, corners = detector.detect(frames[clean[len(clean) // 2]])
            sides = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).min(axis=1)
            kept = sides >= MIN_CHECKED_SIDE_PX
            undistorted = intrinsics.undistort_points(corners[kept].reshape(-1, 2)).reshape(-1, 4, 2)
            for marker, centre in zip(ids[kept], marker_centres(undistorted)):
                errors.append(centre - true_centres[pattern.array * markers_per_array + int(marker)])
    errors = np.array(errors)
    rms = math.sqrt(np.mean(np.sum(errors**2, axis=1)))
    # Measured: 48 markers of 25-54 px, RMS 0.033 px (cam1 0.022, cam2 0.043, cam3 0.026;
    # largest 0.09 px, on cam2, whose lens distortion bends the edges that the detector
    # fits with straight lines: detected in a cv2-undistorted image, such errors drop
    # to ~0.02 px, so they are the detector's, not the renderer's).
    assert len(errors) >= 30
    assert rms < 0.05


def test_frame_rates_counts_and_start_offsets(rendered):
    simulation, _, truth = rendered
    for name, timing in truth["timing"]["cameras"].items():
        path = simulation.out / "videos" / f"{name}.mp4"
        capture = cv2.VideoCapture(str(path))
        assert capture.get(cv2.CAP_PROP_FPS) == pytest.approx(timing["fps"], abs=1e-3)
        assert int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) == timing["frame_count"]
        frames = read_frames(path)
        assert len(frames) == timing["frame_count"]
        # The sequence opens with white frames: the first bright frame marks its start.
        brightness = np.array([frame.mean() for frame in frames])
        first_bright = int(np.argmax(brightness > 0.5 * brightness.max()))
        assert abs(first_bright - timing["start_offset_s"] * timing["fps"]) <= 1.0, name


def window_share(timing: dict, frame: int, boundary_s: float) -> float:
    """Share of a frame's exposure before ``boundary_s`` on the sequence clock."""
    start = timing["first_exposure_start_s"] + frame / timing["fps"]
    return float(np.clip((boundary_s - start) / timing["exposure_s"], 0.0, 1.0))


def spanning_frame(timing: dict, boundary_s: float) -> int:
    return math.floor((boundary_s - timing["first_exposure_start_s"]) * timing["fps"])


def test_frame_across_white_to_black_is_a_blend(rendered):
    simulation, sequence, truth = rendered
    timing = truth["timing"]["cameras"]["cam2"]
    white = next(s for s in sequence.segments if s.kind == "white")
    boundary = (white.last_frame + 1) / sequence.fps
    frame = spanning_frame(timing, boundary)
    share = window_share(timing, frame, boundary)
    assert 0.05 < share < 0.95
    frames = read_frames(simulation.out / "videos" / "cam2.mp4")
    clean_white, blend = frames[frame - 1], frames[frame]
    assert window_share(timing, frame - 1, boundary) == 1.0
    lit = clean_white > 200
    assert lit.mean() > 0.2
    # Ideal photometry (gamma 1): grey level = 255 x the white share of the exposure.
    assert np.median(clean_white[lit]) == pytest.approx(255, abs=2)
    assert np.median(blend[lit]) == pytest.approx(255 * share, abs=3)


def test_frame_across_a_pattern_change_blends_the_two_patterns(rendered):
    simulation, sequence, truth = rendered
    timing = truth["timing"]["cameras"]["cam2"]
    frames = read_frames(simulation.out / "videos" / "cam2.mp4")
    before, after = 0, 1
    boundary = (sequence.patterns[before].last_frame + 1) / sequence.fps
    frame = spanning_frame(timing, boundary)
    share = window_share(timing, frame, boundary)
    assert 0.05 < share < 0.95
    clean = truth["clean_frames"]["cam2"]
    first = frames[clean[before][-1]].astype(float)
    second = frames[clean[after][0]].astype(float)
    blend = frames[frame].astype(float)
    changed = np.abs(first - second) > 100
    assert changed.sum() > 500
    expected = share * first + (1.0 - share) * second
    assert np.mean(np.abs(blend - expected)[changed]) < 3.0
    # Clean frames are not blends: the blend differs from both where the patterns differ.
    assert np.mean(np.abs(blend - first)[changed]) > 30 * min(share, 1 - share)
    assert np.mean(np.abs(blend - second)[changed]) > 30 * min(share, 1 - share)


def cubic_at(image: np.ndarray, x: float, y: float, margin: int = 5) -> float:
    """Cubic spline interpolation at ``(x, y)`` from a patch around it, in float64
    (cv2.remap rounds positions to 1/32 pixel; a patch keeps far NaNs out)."""
    column, row = int(round(x)) - margin, int(round(y)) - margin
    patch = image[row:row + 2 * margin + 1, column:column + 2 * margin + 1]
    return float(map_coordinates(patch, [[y - row], [x - column]], order=3, mode="nearest")[0])


def test_stills_match_clean_video_frames(rendered):
    simulation, sequence, truth = rendered
    pattern = 3
    stills = render_stills(simulation.scene, sequence, pattern, cameras=["cam1", "cam3"])
    for name, still in stills.items():
        clean = truth["clean_frames"][name][pattern]
        frame = read_frames(simulation.out / "videos" / f"{name}.mp4")[clean[0]]
        assert still.shape == frame.shape
        # The video adds only H.264 (crf 18) coding error.
        assert np.mean(np.abs(still.astype(float) - frame)) < 1.0


def test_pixel_maps_follow_opencv_convention():
    """The projector coordinate seen at the (sub-pixel) image of an MSM centre is that
    centre, in a distorted camera. One camera pixel spans about 5 projector pixels
    here, so a half-pixel slip would be off by ~2.5; the bound, 0.01, is the
    interpolation's own error."""
    scene = load_scene("small")
    camera = scene.camera("cam2")
    view = floor_view(camera, scene.projector, scene.floor)
    sequence = short_sequence()
    centres = sequence.centres.reshape(-1, 2)
    seen = project_points(camera, scene.projector.pixels_to_floor(centres))
    pixels = seen.distorted[seen.visible]
    sampled = np.array([[cubic_at(view.projector_x, x, y), cubic_at(view.projector_y, x, y)] for x, y in pixels])
    assert len(pixels) >= 8
    assert np.abs(sampled - centres[seen.visible]).max() < 0.01


def test_atlas_levels_keep_the_centre_of_a_lit_pixel():
    layout = AtlasLayout.for_projector((64, 48), levels=4)
    image = np.zeros((48, 64), np.uint8)
    image[20, 37] = 255
    atlas = layout.build(image)
    for level in range(layout.levels):
        (x0, y0), (width, height) = layout.origins[level], layout.sizes[level]
        part = atlas[y0:y0 + height, x0:x0 + width].astype(float)
        ys, xs = np.mgrid[0:height, 0:width]
        centroid = np.array([(xs * part).sum(), (ys * part).sum()]) / part.sum()
        assert centroid * 2**level - layout.pad == pytest.approx([37, 20], abs=1e-9)


def test_exposure_shares_add_up_and_cover_the_window():
    timeline = ProjectionTimeline.from_sequence(short_sequence())
    shares = timeline.weights(0.09, 0.13)  # white until 0.1 s, then black
    assert shares == pytest.approx({("flat", 255): 0.25, ("flat", 0): 0.75})
    assert timeline.weights(-1.0, -0.5) == {("flat", 0): 1.0}
    assert sum(timeline.weights(0.31, 0.42).values()) == pytest.approx(1.0)


def test_a_file_that_is_not_a_sequence_is_named(tmp_path):
    scene_file = tmp_path / "scene.json"
    save_scene(scene_file, load_scene("small"))
    with pytest.raises(ValueError, match=r"scene\.json.*sequence"):
        simulate_videos("small", scene_file, tmp_path / "out")
    text = tmp_path / "notes.txt"
    text.write_text("hello")
    with pytest.raises(ValueError, match=r"notes\.txt"):
        simulate_videos("small", text, tmp_path / "out")
    assert not (tmp_path / "out" / "truth.json").exists()


def test_an_interrupted_rendering_leaves_no_earlier_truth(tmp_path, monkeypatch):
    """truth.json marks a complete rendering: one interrupted over an earlier rendering's
    folder must not leave the earlier truth beside its own scene.json."""
    import calibproj.simulate.render as render

    out = tmp_path / "out"
    out.mkdir()
    (out / "truth.json").write_text("{}")

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(render, "_render_all", interrupted)
    with pytest.raises(KeyboardInterrupt):
        simulate_videos("small", short_sequence(), out)
    assert (out / "scene.json").is_file() and not (out / "truth.json").exists()


def test_a_camera_that_does_not_see_the_floor_is_named(tmp_path):
    small = load_scene("small")
    skyward = replace(small.cameras[0], name="skyward", position=(0.0, 0.0, 2.0), look_at=(0.0, 0.5, 6.0))
    path = tmp_path / "room.json"
    save_scene(path, replace(small, cameras=(*small.cameras[1:], skyward)))
    with pytest.raises(ValueError, match=r"room\.json.*'skyward'.*does not see the floor"):
        simulate_videos(path, short_sequence(), tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_a_sequence_for_another_projector_is_refused(tmp_path):
    with pytest.raises(ValueError, match="960x540 projector.*1920x1080"):
        simulate_videos("small", short_sequence(projector=(960, 540), marker_px=12.0), tmp_path / "out")


def test_bad_options_are_refused(tmp_path):
    for options in (RenderOptions(crf=60), RenderOptions(preset="fastest"), RenderOptions(supersample=0)):
        with pytest.raises(ValueError):
            simulate_videos("small", short_sequence(), tmp_path / "out", options=options)


def test_command_line_reports_bad_sequence(tmp_path, capsys):
    bad = tmp_path / "sequence.json"
    bad.write_text(json.dumps({"schema": "calibproj.tracks/1"}))
    assert main(["simulate", "--scene", "small", "--sequence", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "sequence.json" in capsys.readouterr().err
    assert main(["simulate", "--scene", "small", "--out", str(tmp_path / "o")]) == 2
    assert "--sequence" in capsys.readouterr().err
