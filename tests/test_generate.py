"""Projection sequence: layout checks, timeline, light codes, sequence.json, frames, video, CLI."""

from __future__ import annotations

import json
import subprocess

import cv2
import numpy as np
import pytest

from calibproj import _core, generate
from calibproj.cli.main import main
from calibproj.sequence import SequenceOptions, build_sequence, default_frames_per_pattern
from calibproj.sequence.codes import code_pair
from calibproj.sequence.layout import MsmLayout
from calibproj.sequence.sequence import Sequence
from calibproj.formats.jsonio import FormatError, read_json, write_json
from calibproj.sequence.markers import MarkerDetector, marker_centres

# A small sequence that still has every ingredient: a non-integer module size
# (scale 1.4), several arrays, markers of 24 px (4 px modules for ArUco 4x4).
SMALL = dict(projector=(480, 270), grid=(2, 4), arrays=3, scales=(1.0, 1.4, 3.0), marker_px=24.0,
             reference_frames=4, code_degree=4)


def small(**overrides) -> Sequence:
    return build_sequence(**{**SMALL, **overrides})


# ------------------------------------------------------------------- timeline


def test_default_frames_per_pattern_covers_a_25_fps_camera():
    assert default_frames_per_pattern(30.0, 25.0) == 3
    assert default_frames_per_pattern(60.0, 30.0) == 4
    assert default_frames_per_pattern(30.0, 60.0) == 1


def test_timeline_segments_patterns_and_codes():
    sequence = small()
    kinds = [segment.kind for segment in sequence.segments]
    assert kinds == ["white", "black", "start_code", "black", "patterns", "black", "end_code", "black", "white"]
    assert sequence.frames_per_pattern == 3
    assert len(sequence.patterns) == 3 * 3
    assert [(p.array, p.scale) for p in sequence.patterns[:4]] == [(0, 1.0), (0, 1.4), (0, 3.0), (1, 1.0)]
    assert sequence.patterns[4].marker_side_px == pytest.approx(24.0 * 1.4)
    patterns = next(s for s in sequence.segments if s.kind == "patterns")
    assert sequence.patterns[0].first_frame == patterns.first_frame
    assert sequence.patterns[-1].last_frame == patterns.last_frame
    assert sequence.start_code.bits != sequence.end_code.bits
    assert len(sequence.start_code.bits) == 15 and sequence.start_code.frames_per_bit == 3
    assert sequence.centres.shape == (3, 8, 2)
    assert sequence.frame_count == sequence.segments[-1].last_frame + 1


@pytest.mark.parametrize("degree", [4, 5, 6])
def test_light_codes_have_a_sharp_peak_and_differ(degree):
    start, end = code_pair(degree)
    length = 2**degree - 1
    assert len(start) == len(end) == length and start != end
    signed_start, signed_end = 2.0 * np.array(start) - 1, 2.0 * np.array(end) - 1
    # Periodic autocorrelation of an m-sequence: length at 0, -1 elsewhere.
    periodic = [np.dot(signed_start, np.roll(signed_start, k)) for k in range(length)]
    assert periodic[0] == length and max(periodic[1:]) == -1
    # Projected between black frames: the peak stands well above every other alignment.
    framed = np.concatenate([-np.ones(length), signed_end, -np.ones(length)])
    assert np.correlate(framed, signed_start, mode="valid").max() < 0.5 * length
    framed = np.concatenate([-np.ones(length), signed_start, -np.ones(length)])
    scores = np.correlate(framed, signed_start, mode="valid")
    assert scores.argmax() == length and np.sort(scores)[-2] < 0.5 * length


def test_frames_show_references_codes_and_patterns():
    sequence = small()
    white = sequence.segments[0]
    assert (sequence.frame(white.first_frame) == 255).all()
    assert (sequence.frame(sequence.segments[1].first_frame) == 0).all()
    code = sequence.start_code
    for bit_index, bit in enumerate(code.bits):
        frame = sequence.frame(code.first_frame + bit_index * code.frames_per_bit + 1)
        assert frame.shape == (270, 480) and frame.dtype == np.uint8
        assert (frame == 255 * bit).all()
    pattern = sequence.patterns[2]
    image = sequence.frame(pattern.first_frame)
    assert image is sequence.frame(pattern.last_frame)  # cached
    assert not image.flags.writeable
    assert image.mean() < 128  # inverted: white markers on black
    with pytest.raises(IndexError):
        sequence.frame(sequence.frame_count)
    with pytest.raises(IndexError):
        sequence.frame(-1)


def test_centres_are_snapped_so_scale_one_edges_are_crisp():
    sequence = small(inverted=False)
    left_edges = sequence.centres - 12.0
    np.testing.assert_allclose(left_edges % 1.0, 0.5)
    image = sequence.pattern_image(0)  # scale 1: every edge on a pixel boundary
    assert set(np.unique(image)) == {0, 255}


# ------------------------------------------------------------------- detection


@pytest.mark.parametrize("markers", ["aruco:4X4_50", "apriltag:tag36h11", "apriltag:tagStandard41h12"])
@pytest.mark.parametrize("inverted", [True, False])
def test_every_marker_detected_at_its_centre_in_every_pattern(markers, inverted):
    """Clean projector frames; measured centre error (diagonal intersection vs the
    sequence's centre): RMS ~0.001-0.003 px, max ~0.03 px at 1920x1080 with the
    default layout; the 0.05 px bound leaves room for the small layout here."""
    sequence = small(markers=markers, inverted=inverted, marker_px=27.0 if "41h12" in markers else 24.0)
    detector = MarkerDetector(markers, inverted=inverted)
    errors = []
    for index, pattern in enumerate(sequence.patterns):
        ids, corners = detector.detect(sequence.pattern_image(index))
        assert ids.tolist() == sequence.markers_shown(index).tolist(), f"pattern {index}"
        errors.extend(np.linalg.norm(marker_centres(corners) - sequence.centres[pattern.array, ids], axis=1))
    assert max(errors) < 0.05


# ------------------------------------------------------------------- bad options


@pytest.mark.parametrize(
    "overrides, message",
    [
        (dict(scales=(1.0, 1.4, 3.0, 4.0)), r"at scale 4 .*overlap"),
        (dict(markers="aruco:9X9_50"), "unknown marker family 'aruco:9X9_50'"),
        (dict(markers="aruco:4X4_1000", grid=(20, 40)), r"at scale 1 .*overlap"),
        (dict(marker_px=100.0), "does not fit a 480x270 projector"),
        (dict(arrays=0), "number of arrays"),
        (dict(markers="apriltag:tag16h5", grid=(4, 8)), "32 ids but apriltag:tag16h5 has only 30"),
        (dict(scales=(1.0, 1.0)), "distinct"),
        (dict(marker_px=3.0), "px modules"),
        (dict(frames_per_pattern=0), "frames_per_pattern"),
        (dict(code_degree=12), "degree"),
        (dict(margin_px=5.0), r"at scale 1 .*leave the 480x270 projector image"),
        (dict(colour="blue"), "unknown sequence option"),
    ],
)
def test_bad_options_raise_clear_value_errors(overrides, message):
    with pytest.raises(ValueError, match=message):
        small(**overrides)


def test_conflicting_markers_can_be_left_out_and_are_recorded():
    sequence = small(scales=(1.0, 6.0), omit_conflicting=True)
    at_six = [p for p in sequence.patterns if p.scale == 6.0]
    assert all(p.omitted for p in at_six)
    assert not any(p.omitted for p in sequence.patterns if p.scale == 1.0)
    index = sequence.patterns.index(at_six[0])
    ids, _ = MarkerDetector("aruco:4X4_50", inverted=True).detect(sequence.pattern_image(index))
    assert ids.tolist() == sequence.markers_shown(index).tolist()
    assert not set(ids.tolist()) & set(at_six[0].omitted)


def test_layout_conflict_helpers():
    layout = MsmLayout(projector=(480, 270), grid=(2, 4), arrays=3, scales=(1.0,), marker_px=24.0)
    assert not layout.outside_image(24.0).any()
    assert layout.outside_image(2000.0).all()
    dx, _ = layout.marker_pitch()
    assert not layout.too_close(dx - 10.0, 5.0).any()
    assert layout.too_close(dx + 1.0, 0.0).any()


# ------------------------------------------------------------------- files


def test_sequence_json_round_trip(tmp_path):
    sequence = generate(tmp_path, video=False, **SMALL)
    assert not (tmp_path / "projection.mp4").exists()
    loaded = Sequence.load(tmp_path / "sequence.json")
    assert loaded == sequence
    # One data model: the core's, which reads and writes the file byte for byte.
    assert isinstance(loaded, _core.ingest.Sequence)
    loaded.save(tmp_path / "again.json")
    assert (tmp_path / "again.json").read_bytes() == (tmp_path / "sequence.json").read_bytes()
    assert read_json(tmp_path / "sequence.json", "sequence", 1)["schema"] == "calibproj.sequence/1"
    np.testing.assert_array_equal(loaded.frame(sequence.patterns[1].first_frame),
                                  sequence.frame(sequence.patterns[1].first_frame))
    assert loaded.markers.spec == "aruco:4X4_50" and loaded.markers.inverted
    assert loaded.start_code == sequence.start_code


def test_loading_other_files_names_the_file(tmp_path):
    generate(tmp_path, video=False, **SMALL)
    body = {key: value for key, value in read_json(tmp_path / "sequence.json", "sequence", 1).items()
            if key != "schema"}
    other = tmp_path / "tracks.json"
    write_json(other, "tracks", 1, {"cameras": {}})
    with pytest.raises(FormatError, match=f"{other}.*tracks file"):
        Sequence.load(other)
    newer = tmp_path / "newer.json"
    write_json(newer, "sequence", 2, body)
    with pytest.raises(FormatError, match=f"{newer}.*newer"):
        Sequence.load(newer)
    broken = tmp_path / "broken.json"
    write_json(broken, "sequence", 1, {**body, "frames_per_pattern": "three"})
    with pytest.raises(FormatError, match=f"{broken}.*frames_per_pattern"):
        Sequence.load(broken)
    inconsistent = tmp_path / "inconsistent.json"
    patterns = [dict(p) for p in body["patterns"]]
    patterns[1]["first_frame"] = patterns[0]["first_frame"]
    write_json(inconsistent, "sequence", 1, {**body, "patterns": patterns})
    with pytest.raises(FormatError, match=f"{inconsistent}.*pattern 1"):
        Sequence.load(inconsistent)
    with pytest.raises(FormatError, match="no such file"):
        Sequence.load(tmp_path / "missing.json")


def _h264_profile(video) -> str:
    return subprocess.run(["ffprobe", "-v", "error", "-select_streams", "v:0", "-show_entries", "stream=profile",
                           "-of", "csv=p=0", str(video)], check=True, capture_output=True, text=True).stdout.strip()


def test_crf_0_makes_a_lossless_projection_for_players_with_the_high_444_profile(tmp_path):
    generate(tmp_path / "default", **SMALL)
    sequence = generate(tmp_path / "lossless", crf=0, **SMALL)
    assert _h264_profile(tmp_path / "default" / "projection.mp4") == "High"
    assert _h264_profile(tmp_path / "lossless" / "projection.mp4") == "High 4:4:4 Predictive"
    capture = cv2.VideoCapture(str(tmp_path / "lossless" / "projection.mp4"))
    for index in range(sequence.frame_count):
        ok, frame = capture.read()
        assert ok
        # Every grey level as rendered, within the range conversion's rounding.
        assert np.abs(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY).astype(int) - sequence.frame(index)).max() <= 1


def test_video_decodes_with_its_frame_count_and_fps(tmp_path):
    sequence = generate(tmp_path, png=True, **SMALL)
    capture = cv2.VideoCapture(str(tmp_path / "projection.mp4"))
    assert capture.get(cv2.CAP_PROP_FPS) == pytest.approx(30.0)
    detector = MarkerDetector("aruco:4X4_50", inverted=True)
    frames = 0
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        grey = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        assert grey.shape == (270, 480)
        # Compression keeps every grey level close to the rendered frame.
        assert np.abs(grey.astype(int) - sequence.frame(frames)).max() <= 40
        pattern = sequence.pattern_index_at(frames)
        if pattern is not None:
            assert detector.detect(grey)[0].tolist() == sequence.markers_shown(pattern).tolist()
        frames += 1
    assert frames == sequence.frame_count
    pngs = sorted((tmp_path / "patterns").glob("pattern_*.png"))
    assert len(pngs) == len(sequence.patterns)
    np.testing.assert_array_equal(cv2.imread(str(pngs[4]), cv2.IMREAD_GRAYSCALE), sequence.pattern_image(4))


def test_options_object_and_overrides():
    options = SequenceOptions(**SMALL)
    sequence = build_sequence(options, markers="apriltag:tag36h11", inverted=False)
    assert sequence.markers.spec == "apriltag:tag36h11" and not sequence.markers.inverted
    assert sequence.layout.grid == (2, 4)


# ------------------------------------------------------------------- command line


def test_cli_writes_the_sequence_and_prints_json(tmp_path, capsys):
    status = main(["generate", "--out", str(tmp_path), "--projector", "480x270", "--grid", "2x4", "--arrays", "2",
                   "--scales", "1,2", "--no-video", "--json", "--markers", "apriltag:tagStandard41h12",
                   "--marker-px", "27", "--no-inverted"])
    assert status == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["points"] == 16 and summary["patterns"] == 4 and summary["video"] is None
    sequence = Sequence.load(tmp_path / "sequence.json")
    assert sequence.markers.spec == "apriltag:tagStandard41h12" and not sequence.markers.inverted


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["--arrays", "0"], "number of arrays"),
        (["--grid", "4by8"], "--grid must look like"),
        (["--scales", "1,1.4,3,4"], "at scale 4"),
        (["--markers", "aruco:nope"], "unknown marker family"),
    ],
)
def test_cli_bad_options_exit_2_with_one_line(tmp_path, capsys, arguments, message):
    grid = [] if "--grid" in arguments else ["--grid", "2x4"]
    status = main(["generate", "--out", str(tmp_path), "--projector", "480x270", "--arrays", "3", "--no-video",
                   *grid, *arguments])
    assert status == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and message in error
    assert not (tmp_path / "sequence.json").exists()
