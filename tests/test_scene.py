"""Scenes: presets, look-at poses, scene.json round trip and validation messages."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from calibproj.simulate.presets import PRESETS
from calibproj.simulate.scene import load_scene, look_at_rotation, read_scene, save_scene, scene_from_json


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_preset_loads_and_round_trips(tmp_path, name):
    scene = load_scene(name, seed=3)
    path = tmp_path / "scene.json"
    save_scene(path, scene)
    assert read_scene(path) == scene
    assert load_scene(path) == scene
    for camera in scene.cameras:
        R = camera.R
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)


def test_paper_rig_cameras_sit_on_their_circles_at_seeded_angles():
    scene = load_scene("paper", seed=7)
    assert len(scene.cameras) == 10
    for camera in scene.cameras:
        radius, height = (2.8, 2.8) if camera.name.startswith("far") else (1.2, 1.4)
        assert math.hypot(*camera.position[:2]) == pytest.approx(radius)
        assert camera.position[2] == pytest.approx(height)
        assert camera.look_at == (0.0, 0.0, 0.0)
        assert camera.fx == 917.0 and camera.resolution == (1920, 1080)
    assert load_scene("paper", seed=7) == scene
    assert load_scene("paper", seed=8) != scene


def test_or_full_is_the_mock_operating_room():
    scene = load_scene("or-full")
    focal = sorted(camera.fx for camera in scene.cameras)
    assert len(scene.cameras) == 9
    assert focal[-1] == 11100.0 and all(abs(f - 915.0) < 5.0 for f in focal[:-1])
    assert all(camera.resolution == (1920, 1080) for camera in scene.cameras)
    # Later video tests rely on varied frame rates and start offsets.
    assert {25.0, 29.97, 30.0, 50.0, 60.0} <= {camera.fps for camera in scene.cameras}
    assert len({camera.start_offset_s for camera in scene.cameras}) == 9
    assert all(camera.exposure_s <= 1.0 / camera.fps for camera in scene.cameras)
    # The projector hangs at ~3 m and covers about 4 x 2.3 m of floor.
    corners = scene.projector.pixels_to_floor([[-0.5, -0.5], [1919.5, 1079.5]])
    extent = np.abs(corners[1] - corners[0])[:2]
    np.testing.assert_allclose(extent, [4.1, 2.3], atol=0.1)


def test_small_preset_is_three_small_cameras():
    scene = load_scene("small")
    assert len(scene.cameras) == 3
    assert all(camera.resolution == (640, 360) for camera in scene.cameras)


def test_look_at_pose_looks_at_the_target_from_the_position():
    rng = np.random.default_rng(0)
    for _ in range(50):
        position, target = rng.uniform(-3, 3, 3), rng.uniform(-3, 3, 3)
        R = look_at_rotation(position, target)
        t = -R @ position
        np.testing.assert_allclose(-R.T @ t, position, atol=1e-12)
        in_camera = R @ target + t
        np.testing.assert_allclose(in_camera[:2], 0.0, atol=1e-12)
        assert in_camera[2] > 0
        # No roll: the image x axis is horizontal and world "up" is image "up" (-y).
        assert R[0, 2] == pytest.approx(0.0, abs=1e-12)
        assert R[1, 2] <= 0.0


def test_straight_down_camera_has_image_top_towards_world_y():
    R = look_at_rotation(np.array([0.5, 0.2, 3.0]), np.array([0.5, 0.2, 0.0]))
    np.testing.assert_allclose(R, [[1, 0, 0], [0, -1, 0], [0, 0, -1]], atol=1e-12)


def test_unknown_preset_names_the_choices():
    with pytest.raises(ValueError, match="no such scene file, and not a preset.*or-full"):
        load_scene("no-such-room")


def _write(tmp_path, document):
    path = tmp_path / "room.json"
    path.write_text(json.dumps(document))
    return path


def _document():
    return {
        "schema": "calibproj.scene/1",
        "floor": {"size_m": [4.0, 3.0]},
        "projector": {"position": [0, 0, 3.0], "look_at": [0, 0, 0], "resolution": [1920, 1080], "fx": 1400},
        "cameras": [{"name": "far1", "position": [2.8, 0, 2.8], "look_at": [0, 0, 0],
                     "resolution": [1920, 1080], "fx": 915}],
    }


def test_scene_file_defaults():
    camera = scene_from_json(_document()).cameras[0]
    assert (camera.fy, camera.cx, camera.cy) == (915.0, 959.5, 539.5)
    assert camera.dist == (0.0,) * 5 and camera.fps == 30.0 and camera.exposure_s == 0.01


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d["cameras"][0].pop("fx"), r"cameras\[0\] \(far1\)\.fx: missing"),
        (lambda d: d["cameras"][0].update(fx=-3), r"cameras\[0\] \(far1\)\.fx: expected a positive number"),
        (lambda d: d["cameras"][0].update(position=[1, 2]), r"position: expected 3 numbers"),
        (lambda d: d["cameras"][0].update(dist=[0.1, 0.2, 0.3]), r"dist: expected 4, 5, 8, 12, 14"),
        (lambda d: d["cameras"][0].update(resolution=[1920.5, 1080]), r"resolution: expected two integers"),
        (lambda d: d["cameras"][0].update(focal=3), r"unknown field\(s\) \['focal'\]"),
        (lambda d: d["cameras"][0].update(name="a/b"), r"cameras\[0\]\.name"),
        (lambda d: d["cameras"][0].update(fps=60, exposure_s=0.02), r"exposure_s: 0.02 s is longer than one frame"),
        (lambda d: d["cameras"][0].update(look_at=[2.8, 0, 2.8]), r"look_at: equals position"),
        (lambda d: d["cameras"][0].update(frame_jitter_s=0.01), r"frame_jitter_s: expected a number in \[0, "),
        (lambda d: d["cameras"][0].update(drop_rate=0.7), r"drop_rate: expected a number in \[0, 0.5\]"),
        (lambda d: d["cameras"].append(dict(d["cameras"][0])), r"cameras: duplicate names \['far1'\]"),
        (lambda d: d.update(cameras=[]), r"cameras: expected a non-empty list"),
        (lambda d: d["projector"].update(look_at=[0, 0, 5]), r"projector: its whole image must fall on the floor"),
        (lambda d: d.pop("floor"), r"floor: missing"),
        (lambda d: d.update(photometric={"gamma": 0}), r"photometric\.gamma: expected a positive number"),
        (lambda d: d.update(photometric={"contrast": 2}), r"photometric\.contrast: expected a number in \[0, 1\]"),
        (lambda d: d.update(schema="calibproj.tracks/1"), r"is a calibproj tracks file, expected scene"),
    ],
)
def test_scene_validation_names_the_file_and_the_field(tmp_path, edit, message):
    document = _document()
    edit(document)
    path = _write(tmp_path, document)
    with pytest.raises(ValueError, match=message) as error:
        read_scene(path)
    assert str(path) in str(error.value)


def test_people_round_trip_and_bad_fields_are_named(tmp_path):
    from dataclasses import replace

    from calibproj.formats.jsonio import FormatError
    from calibproj.simulate.scene import Person

    # Points given as JSON lists, as the presets hold them, compare equal after the round trip too.
    scene = replace(load_scene("small"), people=(Person([-1.0, 0.0], [1.0, 0.5], start_s=2.0, height_m=1.8),))
    save_scene(tmp_path / "scene.json", scene)
    assert read_scene(tmp_path / "scene.json") == scene
    document = json.loads((tmp_path / "scene.json").read_text())
    for field, value, message in (("speed_mps", 0, "people\\[0\\].speed_mps: expected a positive"),
                                  ("albedo", 2, "people\\[0\\].albedo"), ("start", [1], "people\\[0\\].start"),
                                  ("legs", 2, "unknown field")):
        bad = json.loads(json.dumps(document))
        bad["people"][0][field] = value
        with pytest.raises(FormatError, match=message):
            scene_from_json(bad, source="scene.json")


def test_a_projector_lens_bends_its_rays_and_round_trips() -> None:
    from dataclasses import replace

    from calibproj.simulate.warp import floor_view

    scene = load_scene("demo")
    projector = replace(scene.projector, dist=(0.05, 0.01))
    corners = np.array([[0.0, 0.0], [1919.0, 1079.0], [959.5, 539.5]])
    pinhole = scene.projector.pixels_to_floor(corners)
    bent = projector.pixels_to_floor(corners)
    # The corners land farther out (k1 > 0 throws the buffer's corners from rays nearer
    # the axis), the centre where it was.
    assert np.linalg.norm(bent[0, :2]) < np.linalg.norm(pinhole[0, :2])
    np.testing.assert_allclose(bent[2], pinhole[2], atol=1e-12)
    ideal = projector.ideal_pixels(corners)
    np.testing.assert_allclose(projector.buffer_pixels(ideal), corners, atol=1e-6)
    # The renderer reads the buffer where the lens sends each floor point.
    camera = scene.cameras[0]
    view = floor_view(camera, projector, scene.floor)
    inside = np.isfinite(view.projector_x)
    x, y = view.projector_x[inside][::997], view.projector_y[inside][::997]
    floor = projector.pixels_to_floor(np.column_stack([x, y]))
    pinhole_view = floor_view(camera, scene.projector, scene.floor)
    ideal_xy = np.column_stack([pinhole_view.projector_x[inside][::997], pinhole_view.projector_y[inside][::997]])
    np.testing.assert_allclose(projector.buffer_pixels(ideal_xy), np.column_stack([x, y]), atol=1e-6)
    np.testing.assert_allclose(floor[:, 2], 0.0, atol=1e-9)


def test_an_uneven_floor_is_met_by_every_ray_and_round_trips(tmp_path) -> None:
    from dataclasses import replace

    from calibproj.simulate.scene import Floor, FloorRelief
    from calibproj.simulate.warp import floor_view

    relief = FloorRelief(rms_m=0.004, wavelength_m=1.2, seed=3)
    scene = load_scene("demo")
    uneven = replace(scene, floor=Floor(scene.floor.size_m, relief=relief))
    # The relief has the asked-for spread and is smooth on the scale of a marker.
    xs, ys = np.meshgrid(np.linspace(-2, 2, 201), np.linspace(-1.5, 1.5, 151))
    heights = relief.height(np.column_stack([xs.ravel(), ys.ravel()]))
    assert math.sqrt(np.mean(heights**2)) == pytest.approx(0.004, rel=0.35)
    assert np.abs(np.diff(heights.reshape(xs.shape), axis=1)).max() < 0.001  # per 2 cm
    # Projector rays land on the relief, not on z = 0.
    pixels = np.array([[100.0, 80.0], [959.5, 539.5], [1800.0, 1000.0]])
    landed = scene.projector.pixels_to_floor(pixels, uneven.floor)
    np.testing.assert_allclose(landed[:, 2], relief.height(landed[:, :2]), atol=1e-10)
    assert np.abs(landed - scene.projector.pixels_to_floor(pixels)).max() > 1e-4
    # So do camera rays: a pixel's floor point is where the projector's ray through
    # the projector pixel it reads lands.
    camera = scene.cameras[0]
    view = floor_view(camera, scene.projector, uneven.floor)
    inside = np.flatnonzero(np.isfinite(view.projector_x).ravel())[::4999]
    read = np.column_stack([view.projector_x.ravel()[inside], view.projector_y.ravel()[inside]])
    floor_points = np.column_stack([view.floor_x.ravel()[inside], view.floor_y.ravel()[inside]])
    np.testing.assert_allclose(scene.projector.pixels_to_floor(read, uneven.floor)[:, :2], floor_points, atol=1e-8)
    save_scene(tmp_path / "scene.json", uneven)
    assert read_scene(tmp_path / "scene.json") == uneven


@pytest.mark.parametrize(("field", "value", "message"), [
    ("rms_m", 0.2, r"floor\.relief\.rms_m: expected a number in \[0, 0\.05\]"),
    ("wavelength_m", 0.01, r"floor\.relief\.wavelength_m: expected a number of at least 0\.2"),
    ("seed", 1.5, r"floor\.relief\.seed: expected a non-negative integer"),
    ("slope", 1, r"unknown field"),
])
def test_a_bad_floor_relief_is_named(field, value, message) -> None:
    from calibproj.formats.jsonio import FormatError

    document = _document()
    document["floor"]["relief"] = {field: value}
    with pytest.raises(FormatError, match=message):
        scene_from_json(document, source="room.json")


def test_a_camera_change_turns_moves_and_zooms_only_the_named_camera(tmp_path) -> None:
    import subprocess
    import sys

    from calibproj.simulate.scene import CameraChange, load_scene

    scene = load_scene("demo")
    changed = scene.changed({"far2": CameraChange(pan_deg=0.5, tilt_deg=-0.3, shift_m=(0.01, 0.0, -0.02), zoom=1.04)})
    before, after = scene.camera("far2"), changed.camera("far2")
    turn = np.degrees(np.arccos(np.clip((np.trace(after.R @ before.R.T) - 1) / 2, -1, 1)))
    assert turn == pytest.approx(np.hypot(0.5, 0.3), abs=0.01)
    np.testing.assert_allclose(after.center - before.center, [0.01, 0.0, -0.02], atol=1e-12)
    assert after.fx == pytest.approx(1.04 * before.fx) and after.cx == before.cx
    assert all(changed.camera(c.name) == c for c in scene.cameras if c.name != "far2")
    # Tilting up raises the line of sight.
    up = scene.changed({"far1": CameraChange(tilt_deg=1.0)}).camera("far1")
    sight = lambda camera: np.asarray(camera.look_at) - np.asarray(camera.position)  # noqa: E731
    assert np.degrees(np.arcsin(sight(up)[2] / np.linalg.norm(sight(up)))) == pytest.approx(
        np.degrees(np.arcsin(sight(scene.camera("far1"))[2] / np.linalg.norm(sight(scene.camera("far1"))))) + 1.0,
        abs=1e-6)
    with pytest.raises(ValueError, match="no camera far9"):
        scene.changed({"far9": CameraChange(pan_deg=1.0)})
    # The command line: the changed room's truth.
    run = subprocess.run([sys.executable, "-m", "calibproj", "simulate", "--scene", "demo", "--tracks-only",
                          "--arrays", "4", "--change", "far2:pan=0.5,tilt=-0.3,shift=0.01/0/-0.02,zoom=1.04",
                          "--out", str(tmp_path / "room")], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    truth = json.loads((tmp_path / "room" / "truth.json").read_text())
    np.testing.assert_allclose(truth["cameras"]["far2"]["R"], after.R, atol=1e-9)
    bad = subprocess.run([sys.executable, "-m", "calibproj", "simulate", "--scene", "demo", "--tracks-only",
                          "--change", "far2:roll=3", "--out", str(tmp_path / "bad")], capture_output=True, text=True)
    assert bad.returncode == 2 and "roll=3" in bad.stderr and not (tmp_path / "bad").exists()
