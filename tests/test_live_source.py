"""Live sources: a camera stream read over loopback as it arrives, synchronised and
detected while it plays, and recorded unchanged; streams that never open, stall or are
stopped give one line naming the source."""

from __future__ import annotations

import json
import socket
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from calibproj import _core
from calibproj.ingest.videos import ingest
from calibproj.simulate.render import RenderOptions, simulate_videos

from test_ingest import msm_sequence  # the tests folder is on sys.path under pytest

CAMERA = "cam1"


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    """One camera of the small room, rendered with the projection (about 6 s) and 1 s of
    tail, and the same video re-encoded with a key frame every 0.5 s (a camera's stream:
    a receiver that joins late is not left without the stream's parameters) after 1.5 s
    of its first image (a camera streams before the projection starts: a receiver that
    starts late on a loaded machine loses frames of the room, not of the start code)."""
    out = tmp_path_factory.mktemp("live")
    sequence = msm_sequence("aruco:4X4_50")
    simulate_videos("small", sequence, out, seed=7, options=RenderOptions(tail_s=1.0))
    sequence_path = out / "sequence.json"
    sequence.save(sequence_path)
    stream = out / "stream.mkv"
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-i", str(out / "videos" / f"{CAMERA}.mp4"), "-c:v", "libx264",
                    "-preset", "ultrafast", "-g", "15", "-vf", "tpad=start_mode=clone:start_duration=1.5",
                    "-pix_fmt", "yuv420p", str(stream)], check=True)
    return out, sequence_path, stream


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def send(video: Path, url: str, delay_s: float, seconds: float | None = None) -> threading.Thread:
    """Plays the video in real time to ``url`` (MPEG-TS over UDP) after ``delay_s``, as a
    network camera sends: packets unchanged (``seconds``: only the first ones)."""
    def run() -> None:
        time.sleep(delay_s)
        limit = ["-t", str(seconds)] if seconds is not None else []
        subprocess.run(["ffmpeg", "-v", "error", "-re", *limit, "-i", str(video), "-c", "copy", "-f", "mpegts", url],
                       check=False, timeout=60)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def test_a_stream_is_ingested_as_it_arrives_and_recorded_unchanged(room, tmp_path):
    out, sequence, stream = room
    url = f"udp://127.0.0.1:{free_udp_port()}"
    recording = tmp_path / "cam1.mkv"
    source = _core.video.SourceOptions(record_path=str(recording), open_timeout_s=10.0, stall_timeout_s=3.0)
    seen: list[int] = []
    sender = send(stream, url, delay_s=0.5)
    started = time.monotonic()
    live = ingest({CAMERA: url}, sequence, out / "intrinsics", live={CAMERA: source}, progress=False,
                  observer=lambda name, decoded: seen.append(decoded))
    live_s = time.monotonic() - started
    sender.join()
    sent_s = time.monotonic() - started
    camera = live.cameras[CAMERA]
    assert camera.error is None, camera.error
    assert seen and seen[0] == 1
    # The ingest ends with the end light code, before the stream's tail has been sent.
    assert live_s < sent_s

    recorded = ingest({CAMERA: recording}, sequence, out / "intrinsics", progress=False).cameras[CAMERA]
    assert recorded.error is None, recorded.error
    # The recording holds the packets that were decoded live: the same frames, the same
    # light code fit and the same centres.
    for key in ("array", "marker"):
        np.testing.assert_array_equal(getattr(recorded.raw.centres, key), getattr(camera.raw.centres, key))
    np.testing.assert_allclose(recorded.raw.centres.xy, camera.raw.centres.xy, atol=1e-9)
    assert recorded.raw.sync.map.offset == pytest.approx(camera.raw.sync.map.offset, abs=1e-9)

    # Against the file the stream was made from: the same MSMs within what the stream's
    # re-encoding changes.
    original = ingest({CAMERA: stream}, sequence, out / "intrinsics", progress=False).cameras[CAMERA]
    assert len(camera.raw.centres.array) >= 0.95 * len(original.raw.centres.array)
    truth = json.loads((out / "truth.json").read_text())
    assert truth["cameras"]  # the rendered room's truth is there for the capture tests


def test_a_source_that_never_answers_is_named_in_one_line(room):
    out, sequence, _ = room
    url = f"udp://127.0.0.1:{free_udp_port()}"
    source = _core.video.SourceOptions(open_timeout_s=1.0)
    started = time.monotonic()
    camera = ingest({CAMERA: url}, sequence, out / "intrinsics", live={CAMERA: source}, progress=False).cameras[CAMERA]
    assert time.monotonic() - started < 10.0
    assert camera.error.startswith(f"{url}: cannot open the live source (no answer within 1 s")
    assert "\n" not in camera.error


def test_a_refused_connection_is_named_in_one_line(room):
    out, sequence, _ = room
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # closed again: nobody listens there
    url = f"http://127.0.0.1:{port}/camera"
    camera = ingest({CAMERA: url}, sequence, out / "intrinsics", live={CAMERA: _core.video.SourceOptions()},
                    progress=False).cameras[CAMERA]
    assert camera.error.startswith(f"{url}: cannot open the live source")
    assert "refused" in camera.error.lower()


def test_a_stream_that_dies_mid_projection_is_reported_with_the_reason(room, tmp_path):
    out, sequence, stream = room
    url = f"udp://127.0.0.1:{free_udp_port()}"
    recording = tmp_path / "cut.mkv"
    source = _core.video.SourceOptions(record_path=str(recording), open_timeout_s=10.0, stall_timeout_s=1.0)
    sender = send(stream, url, delay_s=0.3, seconds=4.5)
    camera = ingest({CAMERA: url}, sequence, out / "intrinsics", live={CAMERA: source}, progress=False).cameras[CAMERA]
    sender.join()
    assert camera.error.startswith(f"{url}: the source stalled: no data for 1 s before the end of the projection")
    # What arrived is kept, readable.
    info = _core.video.probe(str(recording))
    assert (info.width, info.height) == (640, 360)


def test_a_stop_ends_a_blocked_read_at_once(room):
    out, sequence, _ = room
    url = f"udp://127.0.0.1:{free_udp_port()}"
    source = _core.video.SourceOptions(open_timeout_s=30.0)
    threading.Timer(0.5, source.request_stop).start()
    started = time.monotonic()
    camera = ingest({CAMERA: url}, sequence, out / "intrinsics", live={CAMERA: source}, progress=False).cameras[CAMERA]
    assert time.monotonic() - started < 5.0
    assert source.stop_requested
    assert camera.error == f"{url}: cannot open the live source (stopped while opening)"


@pytest.mark.parametrize("fields, message", [
    ({"open_timeout_s": 0.0}, "open_timeout_s must be in (0, 3600]"),
    ({"stall_timeout_s": float("nan")}, "stall_timeout_s must be in (0, 3600]"),
    ({"live": False, "format": "v4l2"}, "a format and FFmpeg options are for live sources"),
    ({"ffmpeg_options": {"": "1"}}, "FFmpeg option names must be non-empty text"),
])
def test_bad_source_options_are_refused(fields, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace("]", r"\]")):
        _core.video.SourceOptions(**fields)


def test_unknown_source_options_and_formats_are_named(room):
    out, sequence, stream = room
    url = str(stream)  # FFmpeg's file protocol: a source that opens at once
    for source, message in [
        (_core.video.SourceOptions(format="no-such-format"), 'FFmpeg has no input format "no-such-format"'),
        (_core.video.SourceOptions(ffmpeg_options={"no_such_option": "1"}, open_timeout_s=1.0),
         'does not know the option "no_such_option"'),
    ]:
        camera = ingest({CAMERA: url}, sequence, out / "intrinsics", live={CAMERA: source},
                        progress=False).cameras[CAMERA]
        assert camera.error.startswith(url) and message in camera.error


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_an_http_stream_and_a_file_being_written_are_sources_too(room, tmp_path):
    """The other source kinds that run on loopback: an encoder serving MPEG-TS over HTTP
    (FFmpeg's server answers one client), and a recorder's file read while it grows
    (FFmpeg's file protocol with follow=1, ended by the stall timeout)."""
    out, sequence, stream = room
    url = f"http://127.0.0.1:{free_tcp_port()}/camera.ts"
    server = subprocess.Popen(["ffmpeg", "-v", "error", "-re", "-i", str(stream), "-c", "copy", "-f", "mpegts",
                               "-listen", "1", url])
    try:
        source = _core.video.SourceOptions(open_timeout_s=10.0, stall_timeout_s=3.0)
        for _ in range(50):  # until the server listens
            camera = ingest({CAMERA: url}, sequence, out / "intrinsics", live={CAMERA: source},
                            progress=False).cameras[CAMERA]
            if camera.error is None or "refused" not in camera.error.lower():
                break
            time.sleep(0.1)
    finally:
        server.kill()
        server.wait()
    assert camera.error is None, camera.error
    original = ingest({CAMERA: stream}, sequence, out / "intrinsics", progress=False).cameras[CAMERA]
    assert len(camera.raw.centres.array) == len(original.raw.centres.array)

    growing = tmp_path / "recorder.ts"
    writer = subprocess.Popen(["ffmpeg", "-v", "error", "-re", "-i", str(stream), "-c", "copy", "-f", "mpegts",
                               "-flush_packets", "1", str(growing)])
    try:
        while not growing.exists() or growing.stat().st_size == 0:
            time.sleep(0.05)
        source = _core.video.SourceOptions(ffmpeg_options={"follow": "1"}, stall_timeout_s=3.0)
        camera = ingest({CAMERA: f"file:{growing}"}, sequence, out / "intrinsics", live={CAMERA: source},
                        progress=False).cameras[CAMERA]
    finally:
        writer.kill()
        writer.wait()
    assert camera.error is None, camera.error
    assert len(camera.raw.centres.array) == len(original.raw.centres.array)


def test_an_rtsp_stream_pushed_by_an_encoder_is_a_source_too(room):
    """RTSP on loopback: the camera's reader listens (FFmpeg's rtsp_flags=listen) and an
    encoder pushes its stream to it (ANNOUNCE/RECORD, RTP interleaved over TCP), as
    encoders configured to push do; the MSMs are the file's."""
    out, sequence, stream = room
    url = f"rtsp://127.0.0.1:{free_tcp_port()}/camera"

    def push() -> None:
        time.sleep(1.0)  # the reader listens first
        subprocess.run(["ffmpeg", "-v", "quiet", "-re", "-i", str(stream), "-c", "copy", "-f", "rtsp",
                        "-rtsp_transport", "tcp", url], check=False, timeout=60)

    pusher = threading.Thread(target=push, daemon=True)
    pusher.start()
    source = _core.video.SourceOptions(format="rtsp", ffmpeg_options={"rtsp_flags": "listen"}, open_timeout_s=10.0,
                                       stall_timeout_s=3.0)
    camera = ingest({CAMERA: url}, sequence, out / "intrinsics", live={CAMERA: source}, progress=False).cameras[CAMERA]
    pusher.join(timeout=30)
    assert camera.error is None, camera.error
    original = ingest({CAMERA: stream}, sequence, out / "intrinsics", progress=False).cameras[CAMERA]
    assert len(camera.raw.centres.array) == len(original.raw.centres.array)


def test_an_rtsp_server_is_a_source_too(room):
    """RTSP as IP cameras serve it: the camera is the server (GStreamer's rtsp-server on
    loopback, tests/rtsp_server.py) and the reader pulls (DESCRIBE/SETUP/PLAY, RTP
    interleaved over TCP); the MSMs are the file's."""
    out, sequence, stream = room
    port = free_tcp_port()
    server = subprocess.Popen(["/usr/bin/python3", str(Path(__file__).with_name("rtsp_server.py")), str(stream),
                               str(port)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = server.stdout.readline()
        assert line.strip() == "ready", f"the RTSP server did not start: {line}{server.stderr.read()}"
        source = _core.video.SourceOptions(ffmpeg_options={"rtsp_transport": "tcp"}, open_timeout_s=10.0,
                                           stall_timeout_s=3.0)
        camera = ingest({CAMERA: f"rtsp://127.0.0.1:{port}/camera"}, sequence, out / "intrinsics",
                        live={CAMERA: source}, progress=False).cameras[CAMERA]
    finally:
        server.kill()
        server.communicate()
    assert camera.error is None, camera.error
    original = ingest({CAMERA: stream}, sequence, out / "intrinsics", progress=False).cameras[CAMERA]
    assert len(camera.raw.centres.array) == len(original.raw.centres.array)
    np.testing.assert_allclose(camera.raw.centres.xy, original.raw.centres.xy, atol=1e-9)


def _decoded_grey(path: Path) -> list[np.ndarray]:
    reader, frames = _core.video.VideoReader(str(path)), []
    while (frame := reader.grab()) is not None:
        frames.append(frame[1].astype(float))
    return frames


def test_a_stream_encodes_at_the_quality_its_crf_asks(tmp_path):
    """x264 scales each frame's complexity by its duration: a stream that did not give
    it the camera's frame rate was encoded about 5 QP worse than its crf, which froze
    the sensor noise of a still scene from frame to frame (so averaging frames gained
    nothing) and moved the zoomed camera's centres. The same frames through the ffmpeg
    program at the same crf are the reference."""
    rng = np.random.default_rng(0)
    scene = np.full((180, 320), 64.0)
    scene[50:100, 100:200] = 220.0
    frames = [np.clip(scene + rng.normal(0.0, 1.0, scene.shape), 0, 255).round().astype(np.uint8)
              for _ in range(10)]
    writer = _core.video.StreamWriter(str(tmp_path / "stream.ts"), 320, 180, crf=18, fps=30.0)
    for index, frame in enumerate(frames):
        writer.write(frame, index / 30.0)
    writer.close()
    subprocess.run(["ffmpeg", "-v", "error", "-nostdin", "-y", "-f", "rawvideo", "-pix_fmt", "gray", "-s", "320x180",
                    "-r", "30", "-i", "-", "-c:v", "libx264", "-preset", "ultrafast", "-tune", "zerolatency",
                    "-crf", "18", "-pix_fmt", "yuv420p", str(tmp_path / "reference.ts")],
                   input=b"".join(frame.tobytes() for frame in frames), check=True)

    def frame_to_frame(path: Path) -> float:
        decoded = _decoded_grey(path)
        assert len(decoded) == len(frames)
        return float(np.mean([np.std(b - a) for a, b in zip(decoded[1:], decoded[2:])]))

    reference = frame_to_frame(tmp_path / "reference.ts")
    assert reference > 0.1  # the noise is not all frozen at this crf
    assert frame_to_frame(tmp_path / "stream.ts") == pytest.approx(reference, rel=0.2)


def test_a_recording_keeps_the_frame_rate_of_its_source(tmp_path):
    """A 29.97 fps camera recorded into Matroska (millisecond timestamps: 33 and 34 ms
    apart) was read back at 30 fps: 0.1 % off over a projection moved the frames picked
    per pattern onto the pattern changes, and once every pattern was dropped where the
    live ingest of the same packets had kept them all."""
    rate = 30000 / 1001
    writer = _core.video.StreamWriter(str(tmp_path / "camera.ts"), 64, 48, fps=rate)
    for index in range(90):
        writer.write(np.full((48, 64), 16 + index, dtype=np.uint8), index / rate)
    writer.close()
    recording = tmp_path / "camera.mkv"
    reader = _core.video.VideoReader(str(tmp_path / "camera.ts"),
                                     _core.video.SourceOptions(record_path=str(recording)))
    while reader.grab() is not None:
        pass
    del reader
    assert _core.video.probe(str(tmp_path / "camera.ts")).fps == pytest.approx(rate, rel=1e-9)
    assert _core.video.probe(str(recording)).fps == pytest.approx(rate, rel=1e-9)
