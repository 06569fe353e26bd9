"""The virtual operating room: cameras that film, live, what the projector's display
shows.

The projector's output is a virtual X display (Xvfb) of the projector's resolution,
on which ``calibproj capture`` plays the projection full screen as it would on a real
projector. The room grabs that display (FFmpeg's x11grab, through
``calibproj._core.video.VideoReader``), and every camera, on its own clock (start
delay, frame rate, timing jitter, dropped frames), renders its view of the latest
grabbed image through the floor with the offline renderer's optics and photometry
(``calibproj.simulate.warp`` and ``photometric``: lens, blur, vignetting, room light,
floor texture, sensor noise), encodes it with libx264 and sends it as MPEG-TS over UDP
on the loopback interface (``calibproj._core.video.StreamWriter``), as an IP camera
does. What a camera sends is stamped with its own clock, jitter included; a dropped
frame leaves a gap.

``VirtualRoom(scene, folder)`` is a context manager: on entry it starts the display,
the grabber and the cameras and writes, into ``folder``, the cameras' intrinsics, the
scene and its ``truth.json``; ``write_site(...)`` writes a site file naming the
room's streams and display for ``calibproj capture``. Nothing here knows what is
projected: a camera sees whatever the display shows.
"""

from __future__ import annotations

import logging
import os
import shutil
import socket
import subprocess
import threading
import time
from collections import OrderedDict, deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibproj.formats.intrinsics import write_intrinsics_dir
from calibproj.formats.jsonio import write_json
from calibproj.simulate.scene import Scene, load_scene, save_scene

logger = logging.getLogger(__name__)

X_SERVER = "Xvfb"
# Grabs kept (a camera thread may run this many grabs late: 3 s at 60 grabs a second),
# and atlases of them kept for the cameras that film the same moment (4.4 MB each for a
# 960x540 display). On a machine too busy for the room, cameras fall behind by different
# amounts: fewer would make a late camera lose its frames in runs, and fewer atlases
# would have the cameras rebuild each other's, which makes them later still.
GRAB_HISTORY = 180
ATLAS_CACHE = 24
# How long a camera waits for the grab that follows its frame's moment.
GRAB_WAIT_S = 0.5
DISPLAY_START_TIMEOUT_S = 10.0


@dataclass(frozen=True)
class VirtualRoomOptions:
    """Knobs of the virtual room.

    Attributes:
        grab_fps: how often the projector's display is grabbed (at least twice the
            projection's frame rate, so that every projector frame is seen).
        crf: the cameras' x264 quality (18, as the offline renderer encodes).
        key_frame_interval: frames between the cameras' key frames.
        seed: the sensor noise, jitter and drops.
        supersample: samples per camera pixel along each axis (1: the fastest).
    """

    grab_fps: float = 60.0
    crf: int = 18
    key_frame_interval: int = 15
    seed: int = 0
    supersample: int = 1


class VirtualRoom:
    """The room live (see the module docstring); a context manager."""

    def __init__(self, scene: Scene | str | os.PathLike, folder: str | os.PathLike,
                 options: VirtualRoomOptions | None = None) -> None:
        self.scene = scene if isinstance(scene, Scene) else load_scene(scene, seed=0)
        self.folder = Path(folder)
        self.options = options or VirtualRoomOptions()
        self.display = ""
        self.urls: dict[str, str] = {}
        self.sent: dict[str, int] = {}  # frames sent per camera
        # Frames left out per camera because its thread ran later than the grabs kept
        # (the machine too busy for the room), beside those its drop rate left out.
        self.late: dict[str, int] = {}
        self._xvfb: subprocess.Popen | None = None
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        # The display's last grabs (time it was grabbed, wall clock; what it showed, as
        # a content number: a grab like the one before keeps its number) with their
        # images, and the atlases of the last few contents used.
        self._grabs: deque[tuple[float, int]] = deque(maxlen=GRAB_HISTORY)
        self._images: dict[int, np.ndarray] = {}
        self._atlases: OrderedDict[int, np.ndarray] = OrderedDict()
        self._grabs_lock = threading.Lock()
        self._grabbed = threading.Condition(self._grabs_lock)  # notified at every grab
        self._layout_in_use: Any = None
        self._errors: list[str] = []
        self._models: dict[str, tuple[Any, Any, Any]] = {}  # per camera: sampler, response, noise

    def __enter__(self) -> VirtualRoom:
        try:
            self.start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc_info: Any) -> None:
        self.close()

    # ------------------------------------------------------------------ lifetime

    def start(self) -> None:
        from calibproj import _core

        self._write_room()
        self.display = self._start_display()
        width, height = self.scene.projector.resolution
        grabber = _core.video.VideoReader(self.display, _core.video.SourceOptions(
            format="x11grab", ffmpeg_options={"framerate": f"{self.options.grab_fps:g}",
                                              "video_size": f"{width}x{height}", "draw_mouse": "0"}))
        views = {camera.name: self._view(camera) for camera in self.scene.cameras}
        self._layout_in_use = self._layout(views.values())
        self._models = {camera.name: self._camera_model(camera, index, views[camera.name])
                        for index, camera in enumerate(self.scene.cameras)}
        self._spawn("room-grabber", self._grab, grabber)
        started = time.time()
        for index, camera in enumerate(self.scene.cameras):
            url = f"udp://127.0.0.1:{_free_udp_port()}"
            self.urls[camera.name] = url
            writer = _core.video.StreamWriter(url + "?pkt_size=1316", *camera.resolution,
                                              key_frame_interval=self.options.key_frame_interval,
                                              crf=self.options.crf, fps=camera.fps)
            rng = np.random.default_rng([self.options.seed, index])
            self._spawn(f"room-{camera.name}", self._film, camera, writer, started, rng)
        logger.info("virtual room on display %s: %s", self.display,
                    ", ".join(f"{name} {url}" for name, url in self.urls.items()))

    def close(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout=10.0)
        if self._xvfb is not None:
            self._xvfb.terminate()
            try:
                self._xvfb.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                self._xvfb.kill()
            self._xvfb = None

    @property
    def errors(self) -> list[str]:
        """What went wrong in the room's threads (a camera's stream, the grabber)."""
        return list(self._errors)

    def write_site(self, path: str | os.PathLike, sequence: str | os.PathLike, projection: str | os.PathLike,
                   timeouts: dict[str, float] | None = None) -> Path:
        """A site file for ``calibproj capture``: the room's streams, its display, the
        intrinsics written on entry."""
        path = Path(path)
        cameras = {camera.name: {"source": self.urls[camera.name],
                                 "intrinsics": str((self.folder / "intrinsics" / f"{camera.name}.json").resolve())}
                   for camera in self.scene.cameras}
        write_json(path, "site", 1, {"sequence": str(Path(sequence).resolve()),
                                     "projection": str(Path(projection).resolve()),
                                     "projector": {"display": self.display, "video_output": "x11"},
                                     "cameras": cameras, "timeouts": dict(timeouts or {})})
        return path

    # ------------------------------------------------------------------ setup

    def _write_room(self) -> None:
        from calibproj.simulate.truth import truth_document, write_truth

        self.folder.mkdir(parents=True, exist_ok=True)
        write_intrinsics_dir(self.folder / "intrinsics",
                             {camera.name: camera.intrinsics for camera in self.scene.cameras})
        save_scene(self.folder / "scene.json", self.scene)
        empty = (np.zeros(0, dtype=np.int64), np.zeros((0, 3)))
        write_truth(self.folder / "truth.json", truth_document(self.scene, empty, None))

    def _start_display(self) -> str:
        """Starts Xvfb on a free display of the projector's size; its name."""
        if shutil.which(X_SERVER) is None:
            raise RuntimeError(f"the virtual room needs {X_SERVER} (Debian package xvfb: tools/install_deps.sh)")
        width, height = self.scene.projector.resolution
        read_end, write_end = os.pipe()
        try:
            self._xvfb = subprocess.Popen(
                [X_SERVER, "-displayfd", str(write_end), "-screen", "0", f"{width}x{height}x24", "-nolisten", "tcp"],
                pass_fds=(write_end,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            os.close(write_end)
            write_end = -1
            number = _read_line(read_end, DISPLAY_START_TIMEOUT_S)
        finally:
            os.close(read_end)
            if write_end >= 0:
                os.close(write_end)
        if not number.strip().isdigit():
            raise RuntimeError(f"{X_SERVER} did not start a display within {DISPLAY_START_TIMEOUT_S:g} s")
        return f":{number.strip()}"

    def change(self, changes: dict[str, Any]) -> None:
        """Moves or re-zooms cameras while the room runs (``CameraChange`` by name), as a
        bumped lamp or a re-zoomed PTZ camera: from their next frames on they film from
        their new poses. ``truth.json`` is written again; the intrinsics files stay those
        of the cameras as they were, as a user's would."""
        from calibproj.simulate.truth import truth_document, write_truth

        self.scene = self.scene.changed(changes)
        for index, camera in enumerate(self.scene.cameras):
            if camera.name in changes:
                self._models[camera.name] = self._camera_model(camera, index, self._view(camera))
        empty = (np.zeros(0, dtype=np.int64), np.zeros((0, 3)))
        write_truth(self.folder / "truth.json", truth_document(self.scene, empty, None))

    def _render_options(self) -> Any:
        from calibproj.simulate.render import RenderOptions

        return RenderOptions(supersample=self.options.supersample)

    def _view(self, camera: Any) -> Any:
        """Where every sample of the camera looks in the projector image."""
        from calibproj.simulate.warp import floor_view

        return floor_view(camera, self.scene.projector, self.scene.floor, self.options.supersample, self.scene.boxes)

    def _layout(self, views: Any) -> Any:
        """The projector atlas layout, deep enough for the blurriest camera sample (as
        the offline renderer builds it)."""
        from calibproj.simulate.atlas import AtlasLayout
        from calibproj.simulate.warp import pyramid_levels_needed

        blur = self.scene.photometric.blur_px * self.options.supersample
        levels = max(pyramid_levels_needed(view, blur) for view in views)
        return AtlasLayout.for_projector(self.scene.projector.resolution, levels)

    def _camera_model(self, camera: Any, index: int, view: Any) -> tuple[Any, Any, Any]:
        """(sampler, response, noise) of one camera, as the offline renderer builds them."""
        from calibproj.simulate.render import camera_model

        rng = np.random.default_rng([self.options.seed, 1000 + index])
        return camera_model(camera, view, self._layout_in_use, self.scene, self._render_options(), rng)

    def _spawn(self, name: str, target: Any, *args: Any) -> None:
        def run() -> None:
            try:
                target(*args)
            except Exception as error:  # noqa: BLE001 - reported through `errors`
                self._errors.append(f"{name}: {error}")
                logger.error("virtual room: %s: %s", name, error)

        thread = threading.Thread(target=run, name=name, daemon=True)
        thread.start()
        self._threads.append(thread)

    # ------------------------------------------------------------------ threads

    def _grab(self, reader: Any) -> None:
        """Keeps the display's last images with the times x11grab took them."""
        content, last = 0, None
        while not self._stop.is_set():
            frame = reader.grab()
            if frame is None:
                raise RuntimeError(f"display {self.display}: grabbing ended ({reader.end_reason or 'end'})")
            taken, image = frame
            # The display holds each projector frame for several grabs (and the room's
            # whole wait before the projection): the cameras render a new content only.
            if last is None or not np.array_equal(image, last):
                content, last = content + 1, image
            with self._grabbed:
                self._grabs.append((taken, content))
                self._images[content] = last
                for old in [c for c in self._images if c < self._grabs[0][1]]:
                    del self._images[old]
                self._grabbed.notify_all()

    def _shown_at(self, wall_time: float) -> tuple[int, np.ndarray] | None:
        """What the display showed at ``wall_time`` (its last grab before then): its
        content number and atlas. A camera thread that runs late still films its own
        moment."""
        with self._grabbed:
            # A grab at or after the moment first: until then the last one before it may be
            # an older one that a busy grabber has not yet followed.
            self._grabbed.wait_for(lambda: self._stop.is_set() or (self._grabs and self._grabs[-1][0] >= wall_time),
                                   timeout=GRAB_WAIT_S)
            earlier = [content for taken, content in self._grabs if taken <= wall_time]
            if not earlier:
                return None
            content = earlier[-1]
            atlas, image = self._atlases.get(content), self._images[content]
        if atlas is None:
            atlas = self._layout_in_use.build(image)
            with self._grabs_lock:
                self._atlases[content] = atlas
                while len(self._atlases) > ATLAS_CACHE:
                    self._atlases.popitem(last=False)
        return content, atlas

    def _film(self, camera: Any, writer: Any, started: float, rng: np.random.Generator) -> None:
        """One camera: from its start delay on, a frame per period of its own clock (its
        optics as they are now: ``change`` may swap them). Times are wall-clock seconds,
        x11grab's clock."""
        period = 1.0 / camera.fps
        first = started + camera.start_offset_s
        frame = 0
        sent = 0
        spread = camera.frame_jitter_s
        seen: tuple[int, Any, np.ndarray] | None = None  # content, models, the light they gave
        try:
            while True:
                jitter = float(np.clip(rng.normal(0.0, spread), -3 * spread, 3 * spread)) if spread > 0 else 0.0
                due = first + frame * period + jitter
                if self._stop.wait(max(0.0, due - time.time())):
                    break
                dropped = camera.drop_rate > 0 and rng.random() < camera.drop_rate
                shown = None if dropped else self._shown_at(due)
                if shown is not None:
                    content, atlas = shown
                    models = self._models[camera.name]
                    sampler, response, noise = models
                    if seen is None or seen[0] != content or seen[1] is not models:
                        seen = (content, models, sampler.sample(atlas))  # the same content: the same light
                    image = noise.quantise(response.encode(response.irradiance(seen[2])))
                    writer.write(image, due - started)
                    sent += 1
                    self.sent[camera.name] = sent
                elif not dropped:
                    self.late[camera.name] = self.late.get(camera.name, 0) + 1
                frame += 1
        finally:
            writer.close()


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _read_line(fd: int, timeout_s: float) -> str:
    """What a child writes to the pipe ``fd`` up to a newline, or within the timeout."""
    import select

    text = b""
    deadline = time.monotonic() + timeout_s
    while not text.endswith(b"\n"):
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            break
        chunk = os.read(fd, 64)
        if not chunk:
            break
        text += chunk
    return text.decode(errors="replace")
