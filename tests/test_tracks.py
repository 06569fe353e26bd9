"""Tracks: construction, statistics, filtering and tracks.json."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from calibproj.formats.tracks import Tracks, msm_point_ids

CAMERAS = ("a", "b", "c", "d")


def small_tracks() -> Tracks:
    """Points 0..3 of arrays with 32 markers; camera d saw nothing."""
    cameras = ["b", "a", "a", "b", "c", "a", "c"]
    ids = [65, 0, 65, 0, 65, 31, 100]
    xy = np.arange(14, dtype=float).reshape(7, 2)
    return Tracks.from_observations(CAMERAS, cameras, ids, xy, markers_per_array=32)


def test_observations_are_sorted_by_camera_then_point():
    tracks = small_tracks()
    assert tracks.point_ids.tolist() == [0, 31, 65, 100]
    assert tracks.camera_index.tolist() == [0, 0, 0, 1, 1, 2, 2]
    assert tracks.observation_ids().tolist() == [0, 31, 65, 0, 65, 65, 100]
    ids, xy = tracks.observations("a")
    assert ids.tolist() == [0, 31, 65] and xy.tolist() == [[2, 3], [10, 11], [4, 5]]
    assert tracks.keys.tolist() == [[0, 0], [0, 31], [2, 1], [3, 4]]
    assert msm_point_ids(tracks.keys[:, 0], tracks.keys[:, 1], 32).tolist() == tracks.point_ids.tolist()
    with pytest.raises(ValueError, match="MSM keys out of range"):
        msm_point_ids([0], [32], 32)
    camera_index, point_index, xy = tracks.bundle_arrays()
    assert camera_index.dtype == np.int32 and point_index.dtype == np.int32 and xy.shape == (7, 2)


def test_counts_pairs_and_track_lengths():
    tracks = small_tracks()
    assert tracks.counts_per_camera() == {"a": 3, "b": 2, "c": 2, "d": 0}
    assert tracks.track_lengths().tolist() == [2, 1, 3, 1]
    pairs = tracks.pair_counts()
    np.testing.assert_array_equal(np.diag(pairs), [3, 2, 2, 0])
    assert tracks.pair_counts_by_name() == {
        ("a", "b"): 2, ("a", "c"): 1, ("a", "d"): 0, ("b", "c"): 1, ("b", "d"): 0, ("c", "d"): 0,
    }


def test_filtering():
    tracks = small_tracks()
    without_a = tracks.drop_cameras(["a"])
    assert without_a.camera_names == ("b", "c", "d")
    assert without_a.counts_per_camera() == {"b": 2, "c": 2, "d": 0}
    assert without_a.point_ids.tolist() == [0, 65, 100]
    reordered = tracks.keep_cameras(["c", "a"])
    assert reordered.camera_names == ("c", "a")
    assert reordered.observations("a")[0].tolist() == [0, 31, 65]
    assert tracks.drop_points([65]).counts_per_camera() == {"a": 2, "b": 1, "c": 1, "d": 0}
    long_tracks = tracks.with_min_track_length(2)
    assert long_tracks.point_ids.tolist() == [0, 65] and len(long_tracks) == 5
    with pytest.raises(ValueError, match="unknown camera"):
        tracks.drop_cameras(["z"])
    selected = tracks.select(tracks.observation_ids() != 65, ["c", "a", "e"])
    assert selected.camera_names == ("c", "a", "e")
    assert selected.counts_per_camera() == {"a": 2, "c": 1, "e": 0}
    with pytest.raises(ValueError, match="the mask has 2 entries for 7 observations"):
        tracks.select([True, False])


def test_round_trip(tmp_path):
    tracks = small_tracks()
    path = tmp_path / "tracks.json"
    tracks.write(path)
    document = json.loads(path.read_text())
    assert document["schema"] == "calibproj.tracks/1" and document["cameras"] == list(CAMERAS)
    assert document["observations"]["d"] == {"point_ids": [], "xy": []}
    read = Tracks.read(path)
    assert read.camera_names == CAMERAS and read.markers_per_array == 32
    for field in ("point_ids", "camera_index", "point_index", "xy"):
        np.testing.assert_array_equal(getattr(read, field), getattr(tracks, field))


def test_large_generic_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(1)
    cameras = rng.integers(0, 10, 60_000)
    ids = rng.integers(0, 100_000, 60_000)
    unique = np.unique(np.column_stack([cameras, ids]), axis=0)  # one observation per (camera, point)
    xy = rng.uniform(0, 1920, size=(len(unique), 2))
    tracks = Tracks.from_observations([f"cam{i}" for i in range(10)], unique[:, 0], unique[:, 1], xy)
    assert len(tracks) > 50_000
    tracks.write(tmp_path / "eval_tracks.json")
    read = Tracks.read(tmp_path / "eval_tracks.json")
    assert read.markers_per_array is None
    np.testing.assert_array_equal(read.xy, tracks.xy)
    np.testing.assert_array_equal(read.observation_ids(), tracks.observation_ids())
    with pytest.raises(ValueError, match="generic point ids"):
        _ = read.keys


def test_invalid_observations():
    with pytest.raises(ValueError, match="camera 'a' observes point 3 twice"):
        Tracks.from_observations(["a"], [0, 0], [3, 3], np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"unknown camera\(s\) \['z'\]"):
        Tracks.from_observations(["a"], ["z"], [3], np.zeros((1, 2)))
    with pytest.raises(ValueError, match="differ in length"):
        Tracks.from_observations(["a"], [0], [3, 4], np.zeros((2, 2)))
    with pytest.raises(ValueError, match="non-negative"):
        Tracks.from_observations(["a"], [0], [-1], np.zeros((1, 2)))
    with pytest.raises(ValueError, match="duplicate camera names"):
        Tracks.empty(["a", "a"])


def test_a_pixel_that_is_not_finite_cannot_enter_tracks():
    """Found by probing: a NaN set into the xy array of a Tracks was written as a `NaN`
    token, making a tracks.json that no reader (ours included) takes. The arrays are
    read-only views of the core's tracks, and building tracks refuses such a pixel."""
    tracks = Tracks.from_observations(["a", "b"], [0, 1, 0, 1], [3, 3, 4, 4], np.arange(8.0).reshape(4, 2))
    for field in ("xy", "point_ids", "camera_index", "point_index"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(tracks, field)[0] = 1
    xy = np.arange(8.0).reshape(4, 2)
    xy[2, 1] = np.nan
    with pytest.raises(ValueError, match="observations must be finite"):
        Tracks.from_observations(["a", "b"], [0, 1, 0, 1], [3, 3, 4, 4], xy)


def test_views_outlive_their_tracks():
    xy = Tracks.from_observations(["a"], [0, 0], [5, 2], [[1.0, 2.0], [3.0, 4.0]]).xy
    assert xy.tolist() == [[3.0, 4.0], [1.0, 2.0]]


def test_tracks_pickle_for_worker_processes():
    import pickle

    tracks = small_tracks()
    copy = pickle.loads(pickle.dumps(tracks))
    assert copy.camera_names == tracks.camera_names and copy.markers_per_array == 32
    for field in ("point_ids", "camera_index", "point_index", "xy"):
        np.testing.assert_array_equal(getattr(copy, field), getattr(tracks, field))


@pytest.mark.parametrize(("document", "message"), [
    ({"schema": "calibproj.tracks/1", "cameras": ["a"], "observations": {"a": {"point_ids": [1, 2], "xy": [[0, 0]]}}},
     "observations.a: 2 point_ids but 1 xy"),
    ({"schema": "calibproj.tracks/1", "cameras": ["a"], "observations": {"b": {"point_ids": [], "xy": []}}},
     r"camera\(s\) \['b'\] not listed"),
    ({"schema": "calibproj.tracks/1", "cameras": "a", "observations": {}}, "cameras: expected a list"),
    ({"schema": "calibproj.tracks/1", "cameras": ["a"], "observations": {}, "markers_per_array": 0},
     "markers_per_array must be a positive integer"),
    ({"schema": "calibproj.scene/1"}, "is a calibproj scene file, expected tracks"),
])
def test_malformed_files_name_the_file(tmp_path, document, message):
    path = tmp_path / "tracks.json"
    path.write_text(json.dumps(document))
    with pytest.raises(ValueError, match=message) as error:
        Tracks.read(path)
    assert str(path) in str(error.value)


def test_a_json_writer_names_its_file_for_a_value_json_cannot_hold(tmp_path):
    from calibproj.formats.jsonio import write_json

    path = tmp_path / "metrics.json"
    with pytest.raises(ValueError, match=f"^{re.escape(str(path))}: cannot write the metrics file: a value is NaN"):
        write_json(path, "metrics", 1, {"rms": float("nan")})
    assert not path.exists() and list(tmp_path.iterdir()) == []
