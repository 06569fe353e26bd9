"""H.264 video through the ffmpeg command line, fed with raw grey frames on a pipe.

The file appears under its final name only once ffmpeg has finished it, so a failed
or interrupted run never leaves a half-written video behind. Frames are encoded at a
constant rate; given per-frame timestamps (a camera that drops frames or has timing
jitter), the finished stream is remuxed with them (PyAV, no re-encoding), as a
camera's recorder writes its capture times.
"""

from __future__ import annotations

import logging
import os
import shutil
import subprocess
import tempfile
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from calibproj.formats.jsonio import require_replaceable

log = logging.getLogger(__name__)

# x264 constant-rate factor. With the "stillimage" tuning, 4 keeps every grey level
# within ~12 of the rendered frame (14 leaves ringing of up to ~70 levels next to a
# few edges), and the file stays small: the patterns are flat and static. 0 is
# lossless (within 1 level), smaller still (the default sequence: 3.8 MB against
# 6.2 MB) and faster to decode, but needs the High 4:4:4 Predictive profile, which some
# hardware players lack. On the virtual operating room the zoomed camera's centres were
# as far from the truth with either (6 seeds: 0.040 and 0.042 px rms), so 4 stays.
DEFAULT_CRF = 4
# x264 speed/size trade-off; "veryfast" encodes 1080p at ~40 fps on two cores.
DEFAULT_PRESET = "veryfast"
PRESETS = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow", "slower", "veryslow")


def ffmpeg_executable(name: str = "ffmpeg") -> str:
    """Path of the ffmpeg program; RuntimeError with a hint when it is missing."""
    path = shutil.which(name)
    if path is None:
        raise RuntimeError(f"{name} not found on PATH; install Debian's ffmpeg package (tools/install_deps.sh)")
    return path


class GreyVideoWriter:
    """Writes ``uint8`` grey frames ``(height, width)`` to an H.264 MP4 (yuv420p).

    Use as a context manager; the video is complete when the block exits normally.
    """

    def __init__(self, path: str | os.PathLike, size: tuple[int, int], fps: float,
                 crf: int = DEFAULT_CRF, preset: str = DEFAULT_PRESET, timestamps_s: Any = None) -> None:
        if not 0 <= crf <= 51:
            raise ValueError(f"crf must be in [0, 51], got {crf}")
        if preset not in PRESETS:
            raise ValueError(f"unknown x264 preset {preset!r} (choose from {', '.join(PRESETS)})")
        if not fps > 0:
            raise ValueError(f"fps must be positive, got {fps}")
        self.path = Path(path)
        require_replaceable(self.path)
        self.size = (int(size[0]), int(size[1]))
        self.frames_written = 0
        self.timestamps_s = None if timestamps_s is None else np.asarray(timestamps_s, dtype=float)
        if self.timestamps_s is not None and not (np.all(np.isfinite(self.timestamps_s))
                                                  and np.all(np.diff(self.timestamps_s) > 0)):
            raise ValueError("timestamps must be finite and increasing")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        handle, self._partial = tempfile.mkstemp(prefix=f".{self.path.name}.", suffix=".partial",
                                                 dir=self.path.parent)
        os.close(handle)
        self._stderr = tempfile.TemporaryFile()
        rate = Fraction(fps).limit_denominator(1001)
        command = [
            ffmpeg_executable(), "-hide_banner", "-loglevel", "error", "-nostdin", "-y",
            "-f", "rawvideo", "-pix_fmt", "gray", "-s", f"{self.size[0]}x{self.size[1]}",
            "-r", f"{rate.numerator}/{rate.denominator}", "-i", "pipe:0",
            "-c:v", "libx264", "-preset", preset, "-crf", str(crf),
            # Flat synthetic images with sharp edges: less ringing than the film tuning.
            "-tune", "stillimage", "-pix_fmt", "yuv420p",
            # Without B-frames decoding order is display order: remuxed packets keep dts = pts.
            *(["-bf", "0"] if self.timestamps_s is not None else []),
            "-movflags", "+faststart", "-f", "mp4", self._partial,
        ]
        log.debug("running %s", " ".join(command))
        self._process = subprocess.Popen(command, stdin=subprocess.PIPE, stderr=self._stderr)

    def write(self, frame: np.ndarray) -> None:
        if frame.dtype != np.uint8 or frame.shape != (self.size[1], self.size[0]):
            raise ValueError(f"expected a uint8 frame of shape {(self.size[1], self.size[0])}, "
                             f"got {frame.dtype} {frame.shape}")
        try:
            self._process.stdin.write(np.ascontiguousarray(frame).data)
        except BrokenPipeError:
            self._fail("ffmpeg stopped reading frames")
        self.frames_written += 1

    def close(self) -> None:
        """Finish the video and move it to its final name."""
        try:
            self._process.stdin.close()
        except BrokenPipeError:
            pass
        if self._process.wait() != 0:
            self._fail(f"ffmpeg exited with status {self._process.returncode}")
        self._stderr.close()
        if self.timestamps_s is not None:
            if self.frames_written != len(self.timestamps_s):
                self.abort()
                raise RuntimeError(f"{self.path}: {self.frames_written} frames written for "
                                   f"{len(self.timestamps_s)} timestamps")
            try:
                retime_video(self._partial, self.timestamps_s)
            except BaseException:
                self.abort()
                raise
        # mkstemp creates 0600; give the video the permissions a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(self._partial, 0o666 & ~umask)
        os.replace(self._partial, self.path)

    def abort(self) -> None:
        """Stop ffmpeg and delete the partial file."""
        if self._process.poll() is None:
            self._process.kill()
            self._process.wait()
        self._stderr.close()
        Path(self._partial).unlink(missing_ok=True)

    def _fail(self, what: str) -> None:
        self._stderr.seek(0)
        detail = self._stderr.read().decode(errors="replace").strip().splitlines()[-3:]
        self.abort()
        raise RuntimeError(f"{self.path}: {what}" + (f": {' | '.join(detail)}" if detail else ""))

    def __enter__(self) -> GreyVideoWriter:
        return self

    def __exit__(self, exc_type, exc, traceback) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


# Time base of retimed videos: 1/90000 s, MPEG's system clock (timestamps to 11 us).
RETIME_TIME_BASE = Fraction(1, 90000)


def retime_video(path: str | os.PathLike, timestamps_s: np.ndarray) -> None:
    """Give the frames of a video without B-frames the timestamps ``timestamps_s``
    (seconds, one per frame in order) by remuxing it in place (no re-encoding)."""
    import av

    path = Path(path)
    retimed = path.with_name(path.name + ".retimed")
    try:
        with av.open(str(path)) as source, av.open(str(retimed), "w", format="mp4") as target:
            stream_in = source.streams.video[0]
            stream_out = target.add_stream_from_template(stream_in)
            stream_out.time_base = RETIME_TIME_BASE
            frame = 0
            for packet in source.demux(stream_in):
                if packet.size == 0:
                    continue  # the demuxer's end-of-stream marker
                if frame >= len(timestamps_s):
                    raise RuntimeError(f"{path}: more frames than timestamps ({len(timestamps_s)})")
                stamp = int(round(float(timestamps_s[frame]) / RETIME_TIME_BASE))
                packet.pts = packet.dts = stamp
                packet.time_base = RETIME_TIME_BASE
                packet.stream = stream_out
                target.mux(packet)
                frame += 1
            if frame != len(timestamps_s):
                raise RuntimeError(f"{path}: {frame} frames for {len(timestamps_s)} timestamps")
        os.replace(retimed, path)
    finally:
        retimed.unlink(missing_ok=True)
