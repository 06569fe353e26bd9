"""Video decoding with FFmpeg's libraries: the luma the ingest measures and detects on
is the grey level of the frames that were encoded, whatever the pixel format and range
(OpenCV's VideoCapture, which goes through BGR, is off by up to 2 grey levels here)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibproj import _core

SIZE = (96, 64)  # width, height
FRAMES = 12

# Encoder, pixel format: limited-range YUV (cameras), full-range YUV (MJPEG), RGB and
# deep formats (converted by FFmpeg's scaler), grey.
ENCODINGS = {
    "x264_yuv420p": ("libx264", "yuv420p", "mp4"),
    "mjpeg_yuvj420p": ("mjpeg", "yuvj420p", "avi"),
    "png_rgb24": ("png", "rgb24", "mkv"),
    "ffv1_yuv420p10": ("ffv1", "yuv420p10le", "mkv"),
    "ffv1_gray": ("ffv1", "gray", "mkv"),
}


def frames() -> np.ndarray:
    """Grey ramps whose brightness changes from frame to frame, with some colour."""
    rng = np.random.default_rng(3)
    x = np.linspace(0.0, 1.0, SIZE[0])[None, :, None]
    y = np.linspace(0.0, 1.0, SIZE[1])[:, None, None]
    out = []
    for k in range(FRAMES):
        level = 0.15 + 0.7 * k / (FRAMES - 1)
        image = level * (0.6 + 0.4 * x) * (0.8 + 0.2 * y) * np.array([0.9, 1.0, 1.1])
        image = image + rng.normal(0.0, 0.01, image.shape)
        out.append(np.clip(255.0 * image, 0, 255).astype(np.uint8))
    return np.stack(out)


def encode(folder: Path, name: str, video: np.ndarray, rate: str = "25") -> Path:
    codec, pix_fmt, suffix = ENCODINGS[name]
    path = folder / f"{name}.{suffix}"
    extra = ["-qp", "0"] if codec == "libx264" else []
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-f", "rawvideo", "-pix_fmt", "bgr24", "-s",
                    f"{SIZE[0]}x{SIZE[1]}", "-r", rate, "-i", "-", "-c:v", codec, *extra, "-pix_fmt", pix_fmt,
                    str(path)], input=video.tobytes(), check=True)
    return path


@pytest.mark.parametrize("name", sorted(ENCODINGS))
def test_luma_is_the_grey_level_of_the_encoded_frames(tmp_path: Path, name: str) -> None:
    video = frames()
    path = encode(tmp_path, name, video)
    ours = _core.video.luma_signal(str(path), 1.0, 1)
    encoded = np.array([cv2.cvtColor(image, cv2.COLOR_BGR2GRAY).mean() / 255.0 for image in video])
    assert len(ours) == FRAMES
    # Limited-range YUV rounds each pixel to 219 levels: under one grey level on average.
    np.testing.assert_allclose(ours, encoded, rtol=0, atol=0.75 / 255.0)


@pytest.mark.parametrize("name", sorted(ENCODINGS))
def test_luma_measured_on_the_decoded_plane_is_that_of_the_grey_image(tmp_path: Path, name: str) -> None:
    """The sync measures limited-range luma without stretching the frame first (its table
    does it): the same linearised mean as the grey image the detection gets."""
    path = encode(tmp_path, name, frames())
    gamma = 2.2
    ours = _core.video.luma_signal(str(path), gamma, 1, use_timestamps=False)
    reader = _core.video.VideoReader(str(path))
    expected = []
    while (grabbed := reader.grab()) is not None:
        expected.append(np.mean((grabbed[1] / 255.0) ** gamma))
    assert len(ours) == len(expected) == FRAMES
    np.testing.assert_allclose(ours, expected, rtol=1e-6, atol=0)


def test_limited_range_luma_is_stretched_to_full_range_value_by_value(tmp_path: Path) -> None:
    """Every limited-range luma value becomes the full-range grey level FFmpeg's
    conversion gives it, (v - 16) * 255 / 219 rounded and clipped."""
    luma = np.tile(np.arange(256, dtype=np.uint8).reshape(16, 16), (SIZE[1] // 16, SIZE[0] // 16))
    chroma = np.full((SIZE[1] // 2, SIZE[0]), 128, np.uint8)  # both quarter-size planes
    path = tmp_path / "ramp.mp4"
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-f", "rawvideo", "-pix_fmt", "yuv420p", "-s",
                    f"{SIZE[0]}x{SIZE[1]}", "-i", "-", "-c:v", "libx264", "-qp", "0", str(path)],
                   input=np.concatenate([luma, chroma]).tobytes(), check=True)
    grabbed = _core.video.VideoReader(str(path)).grab()
    expected = np.clip(np.rint((luma.astype(float) - 16.0) * 255.0 / 219.0), 0, 255)
    np.testing.assert_array_equal(grabbed[1], expected)


def test_probe_reads_size_rate_and_frame_count(tmp_path: Path) -> None:
    path = encode(tmp_path, "x264_yuv420p", frames(), rate="30000/1001")
    info = _core.video.probe(str(path))
    assert (info.width, info.height) == SIZE
    assert info.fps == pytest.approx(30000 / 1001, rel=1e-6)
    assert info.frame_count == FRAMES


@pytest.mark.parametrize("content", [b"", b"not a video at all" * 100])
def test_unreadable_files_name_the_file(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "broken.mp4"
    path.write_bytes(content)
    with pytest.raises(RuntimeError, match=r"broken\.mp4: cannot open the video"):
        _core.video.luma_signal(str(path), 1.0, 1)
    with pytest.raises(RuntimeError, match=r"missing\.mp4: no such video file"):
        _core.video.probe(str(tmp_path / "missing.mp4"))


def test_a_truncated_video_gives_the_frames_before_the_cut(tmp_path: Path) -> None:
    path = encode(tmp_path, "mjpeg_yuvj420p", frames())
    data = path.read_bytes()
    cut = tmp_path / "cut.avi"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    signal = _core.video.luma_signal(str(cut), 1.0, 1)
    assert 1 < len(signal) < FRAMES
    # The frames before the cut are intact (the last one may be partly decoded).
    whole = _core.video.luma_signal(str(path), 1.0, 1)
    np.testing.assert_allclose(signal[:-1], whole[: len(signal) - 1], rtol=0, atol=1e-12)


def test_ffmpeg_speaks_only_through_the_one_error_line(tmp_path: Path) -> None:
    """Found by probing: FFmpeg's own log lines ("moov atom not found") reached the user
    beside calibproj's message. Its last error is now part of that message."""
    mp4 = tmp_path / "cut.mp4"
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-f", "lavfi", "-i", "testsrc=size=64x48:rate=25", "-frames:v",
                    "10", "-c:v", "mpeg4", str(tmp_path / "whole.mp4")], check=True)
    mp4.write_bytes((tmp_path / "whole.mp4").read_bytes()[:200])  # the header without its moov atom
    script = ("from calibproj import _core\n"
              f"try:\n    _core.video.probe({str(mp4)!r})\n"
              "except RuntimeError as error:\n    print(error)\n")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert result.stderr == ""
    assert result.stdout.strip() == (f"{mp4}: cannot open the video (corrupt, truncated or not a video FFmpeg reads; "
                                     "FFmpeg: moov atom not found)")
