"""provenance.json: when, how and from what a results folder was made; and the report's
sections built on it (provenance, scale source, evaluation)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from calibproj.cli.main import main
from calibproj.formats.file_names import path_as_recorded, safe_file_names
from calibproj.formats.provenance import provenance, read_provenance, write_provenance
from calibproj.version import __version__
from calibproj.simulate import simulate_tracks


def test_inputs_beside_the_results_are_recorded_relative_to_them(tmp_path: Path) -> None:
    results = tmp_path / "project" / "results"
    assert path_as_recorded(tmp_path / "project" / "videos" / "far1.mp4", results) == "../videos/far1.mp4"
    assert path_as_recorded(tmp_path / "elsewhere.json", results) == str((tmp_path / "elsewhere.json").resolve())


def test_a_file_is_identified_by_its_hash(tmp_path: Path) -> None:
    path = tmp_path / "sequence.json"
    path.write_bytes(b"{}")
    record = provenance(command=None, source=tmp_path / "absent.json", sequence=path, intrinsics=tmp_path)
    (tmp_path / "staging").mkdir()
    write_provenance(tmp_path / "staging", tmp_path / "results", record)
    inputs = json.loads((tmp_path / "staging" / "provenance.json").read_text())["inputs"]
    assert inputs["sequence"] == {"path": "../sequence.json", "bytes": 2, "sha256": hashlib.sha256(b"{}").hexdigest()}
    assert inputs["source"] == {"path": "../absent.json"}
    assert inputs["intrinsics"] == {"path": ".."}


def test_a_large_file_is_identified_by_size_and_time(tmp_path: Path) -> None:
    import os

    from calibproj import _core

    video = tmp_path / "far1.mp4"
    with video.open("wb") as stream:
        stream.truncate(_core.formats.max_hashed_bytes + 1)
    os.utime(video, (0, 86400))
    record = provenance(command=["calibproj"], source=tmp_path,
                        videos={"far1": video, "ip": "rtsp://127.0.0.1:8554/far2"})
    (tmp_path / "staging").mkdir()
    write_provenance(tmp_path / "staging", tmp_path / "results", record)
    document = json.loads((tmp_path / "staging" / "provenance.json").read_text())
    assert document["inputs"]["videos"] == {
        "far1": {"path": "../far1.mp4", "bytes": _core.formats.max_hashed_bytes + 1,
                 "modified": "1970-01-02T00:00:00+00:00"},
        "ip": {"source": "rtsp://127.0.0.1:8554/far2"}}
    assert document["calibproj"] == __version__ and document["python"] and document["command"] == ["calibproj"]


def test_camera_names_become_distinct_safe_file_names() -> None:
    names = safe_file_names(["far1", "Far1", "a/b", "../x", ""], prefix="camera_")
    assert names == {"far1": "camera_far1.png", "Far1": "camera_Far1_2.png", "a/b": "camera_a_b.png",
                     "../x": "camera__x.png", "": "camera_camera.png"}


def test_calibrate_records_its_command_inputs_and_the_report_shows_them(tmp_path: Path) -> None:
    simulate_tracks("small", tmp_path / "sim", noise_px=0.3, seed=3)
    argv = ["calibrate", "--tracks", str(tmp_path / "sim" / "tracks.json"), "--intrinsics",
            str(tmp_path / "sim" / "intrinsics"), "--out", str(tmp_path / "r"), "--scale", "camera-height:cam1=2.5"]
    assert main(argv) == 0
    record = read_provenance(tmp_path / "r")
    assert record["command"] == ["calibproj", *argv]
    tracks = tmp_path / "sim" / "tracks.json"
    assert record["inputs"]["source"] == {"path": "../sim/tracks.json", "bytes": tracks.stat().st_size,
                                          "sha256": hashlib.sha256(tracks.read_bytes()).hexdigest()}
    assert record["inputs"]["intrinsics"] == {"path": "../sim/intrinsics"}
    assert record["model"] == "coplanar" and record["options"]["model"] == "coplanar"
    assert record["scale"]["measurement"] == "camera-height:cam1=2.5" and record["scale"]["metres_per_unit"] > 0
    page = (tmp_path / "r" / "report.html").read_text(encoding="utf-8")
    assert "<h2>Provenance</h2>" in page and "calibproj calibrate --tracks" in page
    assert "camera-height:cam1=2.5 (" in page  # the scale's source, with its factor
    # An evaluation saved into the folder appears in its report.
    assert main(["evaluate", str(tmp_path / "r"), "--tracks", str(tmp_path / "sim" / "eval_tracks.json"),
                 "--save"]) == 0
    saved = json.loads((tmp_path / "r" / "evaluation.json").read_text())
    assert saved["schema"] == "calibproj.evaluation/1" and saved["tracks"] == "../sim/eval_tracks.json"
    assert set(saved["success_rate"]) == {"0.5", "2", "5"}
    page = (tmp_path / "r" / "report.html").read_text(encoding="utf-8")
    assert "<h2>Evaluation on independent points</h2>" in page
