"""Boxes in the room (an operating table left in place): rays, shadows, hiding, and the
geometric simulation of the or-table preset against what the geometry says, and the
ingest of rendered videos of a room with a table."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calibproj.formats.jsonio import FormatError
from calibproj.simulate import boxes
from calibproj.simulate.geometric import msm_floor_points, msm_surfaces, simulate_tracks
from calibproj.simulate.presets import preset_document
from calibproj.simulate.scene import Box, scene_from_json

TABLE = Box((0.0, 0.0), (2.0, 0.6, 0.1), bottom_m=0.8)  # top at 0.9 m, x in [-1, 1]


def test_rays_land_on_the_first_surface_they_meet() -> None:
    origin = np.array([0.0, 0.0, 3.0])
    points, surfaces = boxes.first_hits(origin, np.array([[0.0, 0.0, -1.0], [0.5, 0.0, -1.0], [0.0, 0.0, 1.0]]),
                                        [TABLE])
    np.testing.assert_allclose(points[0], [0.0, 0.0, 0.9])
    assert surfaces[0] == boxes.surface_of(0, "top")
    # Past the top's edge (x = 1.05 at its height) and above its side: the floor.
    np.testing.assert_allclose(points[1], [1.5, 0.0, 0.0])
    assert surfaces[1] == boxes.FLOOR
    assert surfaces[2] == -1 and np.all(np.isnan(points[2]))
    side, surface = boxes.first_hits(np.array([3.0, 0.1, 0.85]), np.array([[-1.0, 0.0, 0.0]]), [TABLE])
    np.testing.assert_allclose(side[0], [1.0, 0.1, 0.85])
    assert surface[0] == boxes.surface_of(0, "+x") and boxes.surface_name(int(surface[0])) == "box 0 +x"


def test_shadows_and_hiding() -> None:
    projector = np.array([0.0, 0.0, 3.0])
    under, on_top, beside = [0.3, 0.0, 0.0], [0.3, 0.0, 0.9], [1.6, 0.0, 0.0]
    assert list(boxes.hidden(projector, np.array([under, on_top, beside]), [TABLE])) == [True, False, False]
    assert list(boxes.inside(np.array([[0.0, 0.0, 0.85], [0.0, 0.0, 0.95]]), [TABLE])) == [True, False]


@pytest.mark.parametrize("face, normal, offset", [("top", [0, 0, 1], 0.9), ("bottom", [0, 0, -1], -0.8),
                                                  ("-x", [-1, 0, 0], 1.0), ("+y", [0, 1, 0], 0.3)])
def test_surface_planes(face: str, normal: list[float], offset: float) -> None:
    n, d = boxes.surface_plane([TABLE], boxes.surface_of(0, face))
    np.testing.assert_allclose(n, normal)
    assert d == pytest.approx(offset)


def test_scene_files_with_boxes_round_trip_and_are_checked() -> None:
    document = preset_document("or-table")
    scene = scene_from_json(document)
    assert len(scene.boxes) == 3 and scene.boxes[0].upper[2] == pytest.approx(0.9)
    assert scene_from_json(scene.to_json()).boxes == scene.boxes
    for bad, message in [({"centre": [0, 0]}, "size_m"), ({"centre": [0, 0], "size_m": [1, 1, -1]}, "size_m"),
                         ({"centre": [0, 0], "size_m": [1, 1, 1], "albedo": 2}, "albedo"),
                         ({"centre": [0, 0], "size_m": [1, 1, 1], "colour": 1}, "colour")]:
        with pytest.raises(FormatError, match=message):
            scene_from_json({**document, "boxes": [bad]})


def test_the_or_table_simulation_follows_the_geometry() -> None:
    simulation = simulate_tracks("or-table", None, seed=0, noise_px=0.0)
    scene = simulation.scene
    points = msm_floor_points(scene, simulation.layout)
    surfaces = msm_surfaces(scene, simulation.layout)
    seen = np.unique(simulation.tracks.point_ids)
    on_top = surfaces[seen] == boxes.surface_of(0, "top")
    assert on_top.sum() > 500 and (surfaces[seen] == boxes.FLOOR).sum() > 1000
    # Every point lies on the plane of its surface.
    for surface in np.unique(surfaces[seen]):
        n, d = boxes.surface_plane(scene.boxes, int(surface))
        np.testing.assert_allclose(points[seen[surfaces[seen] == surface]] @ n, d, atol=1e-9)
    # No camera observes a point a box hides from it; the floor under the table top,
    # in its shadow, gets no MSM at all.
    for name in scene.camera_names:
        ids, _ = simulation.tracks.observations(name)
        assert not boxes.hidden(scene.camera(name).center, points[ids], scene.boxes).any(), name
    floor_points = points[seen[surfaces[seen] == boxes.FLOOR]]
    under_top = (np.abs(floor_points[:, 0]) < 1.0) & (np.abs(floor_points[:, 1]) < 0.275)
    assert not under_top.any()
    # Evaluation points are never inside a box.
    assert not boxes.inside(simulation.eval_points, scene.boxes).any()


def test_truth_gives_each_centre_its_surface(tmp_path) -> None:
    import json

    simulate_tracks("or-table", tmp_path, seed=0)
    truth = json.loads((tmp_path / "truth.json").read_text())
    surfaces = np.array(truth["points"]["surface"])
    xyz = np.array(truth["points"]["xyz"])
    top = truth["surfaces"][str(boxes.surface_of(0, "top"))]
    assert top["name"] == "box 0 top" and top["offset"] == pytest.approx(0.9)
    on_top = surfaces == boxes.surface_of(0, "top")
    np.testing.assert_allclose(xyz[on_top, 2], 0.9)


def _rotation_rmse_not_weak(calibration, truth_file) -> float:
    from calibproj.evaluation.comparison import compare

    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as folder:
        calibration.save(folder)
        errors = compare(Path(folder) / "camera_poses.json", truth_file)
    strong = [name for name in errors.cameras if not calibration.metrics[name].weak]
    return float(np.sqrt(np.mean([errors.cameras[name].rotation_deg ** 2 for name in strong])))


@pytest.fixture(scope="module")
def table_room(tmp_path_factory):
    """The demo room with and without its table, calibrated (coplanar model)."""
    from calibproj.registration.driver import register

    folder = tmp_path_factory.mktemp("table")
    out = {}
    for preset in ("demo", "or-table"):
        simulation = simulate_tracks(preset, folder / preset, seed=0, noise_px=0.1)
        out[preset] = (simulation, register(simulation.tracks, simulation.intrinsics), folder / preset / "truth.json")
    return out


def test_the_table_left_in_place_costs_no_accuracy(table_room) -> None:
    simulation, calibration, truth = table_room["or-table"]
    assert calibration.failed == {} and set(calibration.registered) == set(simulation.scene.camera_names)
    with_table = _rotation_rmse_not_weak(calibration, truth)
    without = _rotation_rmse_not_weak(table_room["demo"][1], table_room["demo"][2])
    assert with_table <= 1.2 * without + 0.001
    # Every observation of the table top is kept: it lies on a plane of its own.
    assert all(m.inliers >= 0.99 * m.observations for m in calibration.metrics.values())


def test_the_table_top_is_found_at_its_height(table_room) -> None:
    from calibproj.evaluation.comparison import align_centers
    from calibproj.scale.metric import parse_scale, scale_factor, scaled

    simulation, calibration, _ = table_room["or-table"]
    assert len(calibration.planes) == 1
    # In metres, from the true height of one camera (as a user measures it).
    far1 = simulation.scene.camera("far1")
    metric = scaled(calibration, scale_factor(calibration, parse_scale(f"camera-height:far1={far1.center[2]}"), None))
    top = metric.planes[0]
    assert top.normal[2] > 0.9999
    assert abs(top.offset - 0.9) < 0.002
    # Its points seen twice (one seen once lies wherever its ray meets the floor), brought
    # onto the truth's frame, lie within a millimetre of the true top.
    names = metric.registered
    scale, R, t = align_centers(np.array([metric.center(n) for n in names]),
                                np.array([simulation.scene.camera(n).center for n in names]))
    ids = metric.point_ids
    surfaces = msm_surfaces(simulation.scene, simulation.layout)[ids]
    lengths = dict(zip(simulation.tracks.point_ids.tolist(), simulation.tracks.track_lengths().tolist()))
    on_top = (surfaces == boxes.surface_of(0, "top")) & (np.array([lengths[int(i)] for i in ids]) >= 2)
    in_truth = scale * metric.points[on_top] @ R.T + t
    assert on_top.sum() > 500 and np.abs(in_truth[:, 2] - 0.9).max() < 0.001


def test_the_table_is_in_the_results_and_the_report(tmp_path, capsys) -> None:
    from calibproj.formats.calibration import Calibration
    from calibproj.cli.main import main

    simulate_tracks("or-table", tmp_path / "sim", seed=0, noise_px=0.1)
    code = main(["calibrate", "--tracks", str(tmp_path / "sim" / "tracks.json"), "--intrinsics",
                 str(tmp_path / "sim" / "intrinsics"), "--out", str(tmp_path / "out"),
                 "--scale", "camera-height:far1=2.7"])
    assert code == 0
    assert "plane 1 besides the floor: 0.90" in capsys.readouterr().out
    loaded = Calibration.load(tmp_path / "out")
    assert len(loaded.planes) == 1 and abs(loaded.planes[0].offset - 0.9) < 0.002
    assert "plane 1 besides the floor" in (tmp_path / "out" / "report.html").read_text()


def test_the_renderer_sees_the_table_and_its_shadow() -> None:
    """Each camera sample sees the first surface on its ray: where it meets the table
    top, its projector coordinates are those of that point (computed here directly),
    and floor points the table hides from the projector get no projected light."""
    from calibproj.simulate.warp import floor_view

    scene = scene_from_json(preset_document("or-table"))
    camera = scene.camera("near1")
    view = floor_view(camera, scene.projector, scene.floor, 1, scene.boxes)
    top = view.surface == boxes.surface_of(0, "top")
    assert top.sum() > 1000
    rows, columns = np.nonzero(top)
    pick = np.linspace(0, len(rows) - 1, 25).astype(int)
    pixels = np.column_stack([columns[pick], rows[pick]]).astype(float)
    rays = np.column_stack([camera.intrinsics.normalize(camera.intrinsics.undistort_points(pixels)),
                            np.ones(len(pixels))]) @ camera.R
    depth = (0.9 - camera.center[2]) / rays[:, 2]  # the table top's plane z = 0.9
    points = camera.center + depth[:, None] * rays
    in_projector = (points @ scene.projector.R.T + scene.projector.t) @ scene.projector.K.T
    expected = in_projector[:, :2] / in_projector[:, 2:]
    np.testing.assert_allclose(np.column_stack([view.projector_x[rows[pick], columns[pick]],
                                                view.projector_y[rows[pick], columns[pick]]]), expected, atol=1e-6)
    assert np.allclose(view.reflectance[top], scene.boxes[0].albedo)  # a horizontal top: the floor's light
    # The floor under the table top (its shadow) is seen by the camera but not lit.
    floor = view.surface == boxes.FLOOR
    under = floor & (np.abs(view.floor_x) < 0.9) & (np.abs(view.floor_y) < 0.2)
    assert under.sum() > 100 and not view.in_image[under].any() and view.shadow[under].all()
    # ... and the sampler reads no projector light there.
    from calibproj.simulate.atlas import AtlasLayout
    from calibproj.simulate.warp import CameraSampler

    layout = AtlasLayout.for_projector(scene.projector.resolution, 4)
    sampler = CameraSampler.from_view(view, layout, camera.resolution, 1, 0.5)
    light = sampler.sample(np.ones(layout.shape, dtype=np.float32))
    assert light[under].max() == 0.0 and np.median(light[top]) > 0.99


@pytest.fixture(scope="module")
def small_table_videos(tmp_path_factory):
    """Videos of the small room with a table (top 1.6 x 0.9 m at 0.9 m) in the projection."""
    from calibproj.sequence import build_sequence
    from calibproj.simulate.render import simulate_videos

    document = preset_document("small")
    document["boxes"] = [{"centre": [0.0, 0.0], "size_m": [1.6, 0.9, 0.08], "bottom_m": 0.82, "albedo": 0.75}]
    out = tmp_path_factory.mktemp("small-table")
    sequence = build_sequence(markers="aruco:4X4_50", arrays=8, scales=(1.0, 1.5, 2.0), marker_px=80.0,
                              code_degree=4, reference_frames=8)
    simulate_videos(scene_from_json(document), sequence, out, seed=7)
    return out, sequence, json.loads((out / "truth.json").read_text())


def _table_top_centres(result, truth) -> tuple[int, int, float]:
    """MSMs on the table top kept over all cameras, those the truth shows, and the largest
    error of any kept centre (px)."""
    xyz = np.asarray(truth["points"]["xyz"])
    per_array = truth["points"]["markers_per_array"]
    kept = shown = 0
    worst = 0.0
    for name, camera in result.cameras.items():
        assert camera.ok, camera.error
        seen = truth["image_points"][name]
        true_xy = dict(zip(seen["ids"], np.asarray(seen["undistorted"]).reshape(-1, 2)))
        shown += int((xyz[seen["ids"], 2] > 0.5).sum())
        centres = camera.raw.centres
        ids = np.asarray(centres.array) * per_array + np.asarray(centres.marker)
        kept += int((xyz[ids, 2] > 0.5).sum())
        worst = max(worst, max(float(np.linalg.norm(xy - true_xy[int(i)])) for i, xy in zip(ids, centres.xy)))
    return kept, shown, worst


def test_the_ingest_finds_the_markers_on_the_table_top(small_table_videos) -> None:
    """Markers on the table top are not where the floor's homography puts them: whole
    frames explored now and then find them, the table's own homography then plans them,
    and markers folded over its edge are not searched or kept."""
    from calibproj.ingest.videos import ingest
    from calibproj.ingest.options import IngestOptions

    out, sequence, truth = small_table_videos
    explored = ingest(out / "videos", sequence, out / "intrinsics", options=IngestOptions(), progress=False)
    kept, shown, worst = _table_top_centres(explored, truth)
    assert kept >= 0.25 * shown and worst < 1.0
    for camera in explored.cameras.values():
        assert camera.raw.patterns_in_regions > 0
        assert sum(scale.folded for scale in camera.raw.scales) > 0
    report = explored.report()["cameras"]
    assert all("folded" in scale for camera in report.values() for scale in camera["scales"])
    # Planned with the floor's homography alone, the table top's markers are never found.
    on_floor_only = ingest(out / "videos", sequence, out / "intrinsics", options=IngestOptions(explore_interval=0),
                           progress=False)
    assert _table_top_centres(on_floor_only, truth)[0] == 0


def test_explorations_space_out_only_while_nothing_beyond_the_floor_is_found(small_table_videos, tmp_path) -> None:
    """Whole frames cost far more than regions: in a room with nothing but the floor the
    explorations space out (fewer whole frames, no fewer MSMs); with a table top in view
    they stay as frequent as exploring every array (its MSMs all kept)."""
    from calibproj.ingest.videos import ingest
    from calibproj.ingest.options import IngestOptions
    from calibproj.sequence import build_sequence
    from calibproj.simulate.render import simulate_videos

    every_array = IngestOptions(explore_max_interval=1)
    floor = tmp_path / "floor"
    sequence = build_sequence(markers="aruco:4X4_50", arrays=24, scales=(1.0, 1.5, 2.0), marker_px=80.0,
                              code_degree=4, reference_frames=8)
    simulate_videos(scene_from_json(preset_document("small")), sequence, floor, seed=7)
    spaced, dense = (ingest(floor / "videos", sequence, floor / "intrinsics", options=options, progress=False)
                     for options in (IngestOptions(), every_array))
    for name, camera in spaced.cameras.items():
        assert camera.raw.patterns_whole_frame < dense.cameras[name].raw.patterns_whole_frame
        assert len(camera.raw.centres.array) >= 0.98 * len(dense.cameras[name].raw.centres.array)

    out, sequence, truth = small_table_videos
    with_table = {options.explore_max_interval: _table_top_centres(
        ingest(out / "videos", sequence, out / "intrinsics", options=options, progress=False), truth)[0]
        for options in (IngestOptions(), every_array)}
    assert with_table[IngestOptions().explore_max_interval] >= 0.95 * with_table[1] > 0
