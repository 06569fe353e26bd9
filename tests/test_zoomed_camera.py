"""The camera zoomed onto the surgical field, from rendered videos: zoomed to 10,500 px on
the table of the demo room, it sees 4 centres of a sparse first projection (16 arrays,
scales 1-8). It is registered through the projector and reported weak with a sigma that
holds its error; the short extra projection `calibproj generate --densify` plans for it
makes it known as well as the others, within its sigma."""

from __future__ import annotations

from dataclasses import replace

import pytest

from calibproj.evaluation.comparison import rotation_errors_to_reference
from calibproj.pipeline import calibrate
from calibproj.sequence import build_sequence
from calibproj.sequence.densify import DensifyOptions, densify
from calibproj.simulate.render import simulate_videos
from calibproj.simulate.scene import load_scene

ZOOM_PX = 10_500.0
CAMERAS = ("far1", "far2", "far4", "near1", "ceiling")


def rotation_error_to_reference_deg(calibration, scene, name: str) -> float:
    """The camera's rotation error relative to the reference camera (the gauge of the
    covariance, rotation sigma 0), as its sigma is."""
    reference = next(n for n in calibration.poses if calibration.metrics[n].rotation_sigma_deg == 0.0)
    truth = {camera.name: camera.R for camera in scene.cameras}
    return rotation_errors_to_reference(calibration.poses, reference, truth)[name]


@pytest.fixture(scope="module")
def room(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("zoomed")
    scene = load_scene("demo")
    cameras = [replace(c, fx=ZOOM_PX, fy=ZOOM_PX) if c.name == "ceiling" else c
               for c in scene.cameras if c.name in CAMERAS]
    scene = replace(scene, cameras=cameras)
    sequence = build_sequence(arrays=16)
    sequence.save(folder / "sequence.json")
    simulate_videos(scene, sequence, folder / "first", seed=0)
    first = calibrate(folder / "first" / "videos", folder / "first" / "intrinsics", sequence=folder / "sequence.json",
                      out=folder / "results", report=False, progress=False)
    dense, plans = densify(folder / "results", sequence)
    dense.save(folder / "dense.json")
    simulate_videos(scene, dense, folder / "dense", seed=1)
    merged = calibrate(folder / "dense" / "videos", folder / "first" / "intrinsics", sequence=folder / "dense.json",
                       out=folder / "merged", report=False, progress=False, merge=folder / "results")
    return {"scene": scene, "sequence": sequence, "first": first, "dense": dense, "plans": plans, "merged": merged}


def test_a_few_centres_register_the_zoomed_camera_as_weak_with_an_honest_sigma(room) -> None:
    first, scene = room["first"], room["scene"]
    assert sorted(first.registered) == sorted(CAMERAS)
    metrics = first.metrics["ceiling"]
    assert 4 <= metrics.inliers <= 6
    assert metrics.weak
    assert rotation_error_to_reference_deg(first, scene, "ceiling") <= 3.0 * metrics.rotation_sigma_deg


def test_after_densification_the_zoomed_camera_is_known_within_its_sigma(room) -> None:
    assert [plan.footprint.camera for plan in room["plans"]] == ["ceiling"]
    assert room["dense"].duration_s <= DensifyOptions().max_seconds
    merged, scene = room["merged"], room["scene"]
    metrics = merged.metrics["ceiling"]
    assert not metrics.weak
    assert metrics.inliers >= 100
    for name in CAMERAS:
        sigma = merged.metrics[name].rotation_sigma_deg
        if sigma > 0.0:
            assert rotation_error_to_reference_deg(merged, scene, name) <= 3.0 * sigma, name
