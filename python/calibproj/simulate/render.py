"""Rendered simulation: the videos that the cameras of a scene record while the
projector plays a sequence, with intrinsics and ground truth.

For every camera, each distinct projector content (an MSM pattern, a white or black
frame) is warped once through projector -> floor -> camera, lens distortion
included (``calibproj.simulate.warp``), and turned into irradiance
(``calibproj.simulate.photometric``). A camera frame is the exposure-weighted
average of the contents shown during its exposure (``calibproj.simulate.timeline``),
so cameras at any frame rate and start offset are not synchronised with the
projector and a frame across a pattern change is a blend. Frames are rendered at
the camera's resolution (``supersample`` > 1 integrates several samples per pixel)
and encoded to H.264 by the ffmpeg program.

What real cameras and rooms add comes from the scene (``calibproj.simulate.scene``): a
rolling shutter blends per row, automatic exposure scales each frame by the gain its
predecessors set (``ExposureControl``), a textured floor multiplies the light by its
albedo, and a camera that drops frames or jitters gets its true exposure starts as
container timestamps (the video is remuxed, not re-encoded). ``truth.json`` records
all of it.

All cameras advance together through the sequence in chunks of ``chunk_s`` seconds:
each projector content is drawn once for all of them, camera frames are rendered
in threads (OpenCV and numpy release the GIL) and every camera's encoder runs as
its own process.

Output folder::

    videos/<camera>.mp4      H.264, yuv420p, at the camera's frame rate
    intrinsics/<camera>.json
    scene.json               the realised scene
    eval_tracks.json         observations of evaluation points in the working volume
    truth.json               poses, plane, projector, MSM centres, timing (written last)
"""

from __future__ import annotations

import logging
import math
import os
import time
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor, wait
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from calibproj.formats.intrinsics import write_intrinsics_dir
from calibproj.formats.jsonio import FormatError
from calibproj.simulate.atlas import AtlasLayout
from calibproj.simulate.contents import AtlasStore
from calibproj.simulate.geometric import evaluation_tracks
from calibproj.simulate.floor_texture import floor_albedo
from calibproj.simulate.people import PeopleInView, ProjectorLight
from calibproj.simulate.photometric import CameraResponse, ExposureControl, SensorNoise, vignetting_gain
from calibproj.simulate.scene import Camera, Floor, Photometric, Scene, load_scene, save_scene
from calibproj.simulate.timeline import CameraClock, ContentKey, ProjectionTimeline
from calibproj.simulate.truth import write_truth
from calibproj.simulate.video_truth import video_truth_document
from calibproj.simulate.warp import CameraSampler, FloorView, floor_view, pyramid_levels_needed

logger = logging.getLogger(__name__)

# x264 constant-rate factor: 18 is x264's "visually lossless"; lower is better and larger.
DEFAULT_CRF = 18
# The encoder is most of the cost of a render; "ultrafast" is 3-4x faster than
# "veryfast" on noisy frames, at the price of larger files for the same quality.
DEFAULT_PRESET = "ultrafast"
DEFAULT_TAIL_S = 0.5
DEFAULT_CHUNK_S = 2.0
# Corners of a ChArUco board are located to about a tenth of a pixel.
DEFAULT_EVAL_NOISE_PX = 0.1
# Warped contents kept per camera besides the flat ones (consecutive frames share a few).
CAMERA_CACHE_SIZE = 6
# Spawn key of the random streams of frame timing (apart from the noise streams).
TIMING_STREAM = 1000

# Every effect off: frames show the projector's light exactly (for accuracy tests).
IDEAL_PHOTOMETRIC = Photometric(ambient=0.0, contrast=1.0, noise_std=0.0, blur_px=0.0, vignetting=0.0, gamma=1.0)


@dataclass(frozen=True)
class RenderOptions:
    """Knobs of the renderer.

    Attributes:
        crf: x264 constant-rate factor (0 lossless .. 51; default 18, high quality).
        preset: x264 preset (default ``ultrafast``).
        supersample: samples per pixel along each axis (default 1: render at the
            camera's resolution, each pixel's footprint filtered by the pyramid).
        tail_s: seconds every camera keeps recording after the sequence ends.
        chunk_s: sequence seconds rendered between two synchronisations of the cameras.
        threads: worker threads for camera frames; ``None`` = one per camera.
        fresh_noise: draw new sensor noise for every frame instead of reusing two
            pre-drawn fields at random offsets (slower, same statistics).
        photometric: overrides the scene's photometric settings (``IDEAL_PHOTOMETRIC``
            turns every effect off).
        eval_noise_px: noise (standard deviation per coordinate, pixels) of the
            observations in ``eval_tracks.json``: points in the working volume that
            ``calibproj evaluate`` triangulates, as a board recorded after the
            projection would give them (default 0.1).
    """

    crf: int = DEFAULT_CRF
    preset: str = DEFAULT_PRESET
    supersample: int = 1
    tail_s: float = DEFAULT_TAIL_S
    chunk_s: float = DEFAULT_CHUNK_S
    threads: int | None = None
    fresh_noise: bool = False
    photometric: Photometric | None = None
    eval_noise_px: float = DEFAULT_EVAL_NOISE_PX

    def check(self) -> None:
        from calibproj.sequence.video import PRESETS

        if not 0 <= self.crf <= 51:
            raise ValueError(f"crf must be in [0, 51], got {self.crf}")
        if self.preset not in PRESETS:
            raise ValueError(f"unknown x264 preset {self.preset!r} (choose from {', '.join(PRESETS)})")
        if not (isinstance(self.supersample, int) and 1 <= self.supersample <= 8):
            raise ValueError(f"supersample must be an integer in [1, 8], got {self.supersample}")
        if not self.tail_s >= 0:
            raise ValueError(f"tail must be >= 0 s, got {self.tail_s}")
        if not self.chunk_s > 0:
            raise ValueError(f"chunk must be > 0 s, got {self.chunk_s}")
        if self.threads is not None and self.threads < 1:
            raise ValueError(f"threads must be at least 1, got {self.threads}")
        if not self.eval_noise_px >= 0:
            raise ValueError(f"eval noise must be >= 0 px, got {self.eval_noise_px}")


@dataclass(frozen=True)
class CameraVideo:
    """One rendered video."""

    path: Path
    resolution: tuple[int, int]
    fps: float
    frame_count: int
    size_bytes: int
    gains: tuple[float, ...] = ()  # per recorded frame, with automatic exposure


@dataclass(frozen=True)
class VideoSimulation:
    """What ``simulate_videos`` wrote, and how long it took."""

    out: Path
    scene: Scene
    videos: dict[str, CameraVideo]
    elapsed_s: float

    @property
    def frame_count(self) -> int:
        return sum(video.frame_count for video in self.videos.values())

    @property
    def frames_per_second(self) -> float:
        """Camera frames rendered and encoded per second of wall time."""
        return self.frame_count / self.elapsed_s if self.elapsed_s > 0 else math.inf

    @property
    def size_bytes(self) -> int:
        return sum(video.size_bytes for video in self.videos.values())


def simulate_videos(
    scene: Scene | str | os.PathLike,
    sequence: Any,
    out: str | os.PathLike,
    *,
    seed: int = 0,
    options: RenderOptions | None = None,
    progress: bool = False,
) -> VideoSimulation:
    """Render every camera's video of a projection sequence, with ground truth.

    Args:
        scene: a ``Scene``, a preset name or a scene file (presets draw their random
            parts from ``seed``).
        sequence: a ``calibproj.sequence.Sequence`` or the path of its ``sequence.json``.
        out: output folder (created if needed).
        seed: seed of every random draw (sensor noise, the preset's random parts).
        options: renderer knobs (``RenderOptions``).
        progress: show a progress bar per camera.

    Raises:
        ValueError: bad options, a file that is not a scene or a sequence, a sequence
            made for another projector resolution, or a camera that does not see the
            floor; the message names the file or camera.
    """
    options = options or RenderOptions()
    options.check()
    started = time.perf_counter()
    scene, scene_source = _load_scene(scene, seed)
    if options.photometric is not None:
        scene = replace(scene, photometric=options.photometric)
    sequence = _load_sequence(sequence)
    _check_projector(scene, scene_source, sequence)
    timeline = ProjectionTimeline.from_sequence(sequence)
    clocks = {camera.name: _clock(camera, index, timeline, options.tail_s, scene_source, seed)
              for index, camera in enumerate(scene.cameras)}
    views = _floor_views(scene, scene_source, options)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    # truth.json, written last, marks a complete rendering: an earlier one's must not vouch
    # for this one's scene.json while it renders (or after it is interrupted).
    (out / "truth.json").unlink(missing_ok=True)
    write_intrinsics_dir(out / "intrinsics", {camera.name: camera.intrinsics for camera in scene.cameras})
    save_scene(out / "scene.json", scene)
    videos = _render_all(scene, sequence, timeline, clocks, views, out / "videos", seed, options, progress)
    settings = {"seed": seed, "sequence_markers": sequence.markers.spec, **_settings_json(options)}
    gains = {name: video.gains for name, video in videos.items()}
    write_truth(out / "truth.json", video_truth_document(scene, sequence, timeline, clocks, settings, gains))
    point_rng, noise_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    evaluation_tracks(scene, point_rng, noise_rng, options.eval_noise_px)[1].write(out / "eval_tracks.json")
    simulation = VideoSimulation(out, scene, videos, time.perf_counter() - started)
    logger.info("rendered %d frames of %d cameras in %.1f s (%.1f frames/s), %.1f MB",
                simulation.frame_count, len(videos), simulation.elapsed_s, simulation.frames_per_second,
                simulation.size_bytes / 1e6)
    return simulation


def render_stills(
    scene: Scene | str | os.PathLike,
    sequence: Any,
    pattern: int,
    *,
    cameras: list[str] | None = None,
    seed: int = 0,
    options: RenderOptions | None = None,
) -> dict[str, np.ndarray]:
    """One frame per camera exposed wholly while pattern ``pattern`` is shown, made
    exactly as video frames are (lens, photometry, noise) but without a video.

    Args:
        scene, sequence, seed, options: as for ``simulate_videos`` (encoder options unused).
        pattern: index into the sequence's patterns.
        cameras: names of the cameras to render (default all, in scene order).

    Returns:
        Camera name -> ``uint8`` grey image.
    """
    options = options or RenderOptions()
    options.check()
    scene, scene_source = _load_scene(scene, seed)
    if options.photometric is not None:
        scene = replace(scene, photometric=options.photometric)
    if cameras is not None:
        scene = scene.subset(list(cameras))
    sequence = _load_sequence(sequence)
    _check_projector(scene, scene_source, sequence)
    if not 0 <= pattern < len(sequence.patterns):
        raise ValueError(f"pattern {pattern} outside the sequence's patterns 0..{len(sequence.patterns) - 1}")
    views = _floor_views(scene, scene_source, options)
    layout = _atlas_layout(scene, views, options)
    atlas = layout.build(sequence.pattern_image(pattern))
    stills = {}
    for camera, rng in zip(scene.cameras, _noise_generators(seed, len(scene.cameras))):
        sampler, response, noise = camera_model(camera, views[camera.name], layout, scene, options, rng)
        stills[camera.name] = noise.quantise(response.encode(response.irradiance(sampler.sample(atlas))))
    return stills


def _settings_json(options: RenderOptions) -> dict[str, Any]:
    settings = asdict(options)
    settings["photometric"] = None if options.photometric is None else asdict(options.photometric)
    return settings


def _load_scene(scene: Scene | str | os.PathLike, seed: int) -> tuple[Scene, str]:
    if isinstance(scene, Scene):
        return scene, "scene"
    from calibproj.simulate.presets import PRESETS

    source = f"preset {scene!r}" if isinstance(scene, str) and scene in PRESETS else str(scene)
    return load_scene(scene, seed=seed), source


def _load_sequence(sequence: Any) -> Any:
    from calibproj.sequence.sequence import Sequence

    if isinstance(sequence, Sequence):
        return sequence
    if sequence is None:
        raise ValueError("rendering videos needs a projection sequence (sequence.json from calibproj generate)")
    path = Path(sequence)
    if not path.is_file():
        raise FormatError(f"{path}: no such sequence file")
    return Sequence.load(path)


def _check_projector(scene: Scene, scene_source: str, sequence: Any) -> None:
    if tuple(sequence.projector) != tuple(scene.projector.resolution):
        width, height = sequence.projector
        scene_width, scene_height = scene.projector.resolution
        raise ValueError(f"the sequence is made for a {width}x{height} projector but the projector of "
                         f"{scene_source} is {scene_width}x{scene_height}; generate the sequence with "
                         f"--projector {scene_width}x{scene_height}")


def _clock(camera: Camera, index: int, timeline: ProjectionTimeline, tail_s: float, scene_source: str,
           seed: int) -> CameraClock:
    clock = CameraClock.covering(camera.fps, camera.start_offset_s, camera.exposure_s, timeline.duration_s, tail_s,
                                 camera.readout_s)
    if clock.frame_count < 1:
        raise ValueError(f"{scene_source}: camera {camera.name!r} starts {-camera.start_offset_s:.3f} s after a "
                         f"sequence of {timeline.duration_s:.3f} s has ended and records nothing")
    if camera.frame_jitter_s > 0 or camera.drop_rate > 0:
        # A stream of its own per camera: timing effects leave every other draw as it was.
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(TIMING_STREAM, index)))
        clock = clock.with_timing(camera.frame_jitter_s, camera.drop_rate, rng)
    return clock


def _floor_views(scene: Scene, scene_source: str, options: RenderOptions) -> dict[str, FloorView]:
    """Trace every camera (in threads); a camera that sees no floor is an error."""
    def trace(camera: Camera) -> FloorView:
        return floor_view(camera, scene.projector, scene.floor, options.supersample, scene.boxes)

    with ThreadPoolExecutor(max_workers=_worker_count(options, len(scene.cameras))) as pool:
        views = dict(zip(scene.camera_names, pool.map(trace, scene.cameras)))
    for camera in scene.cameras:
        view = views[camera.name]
        if not view.on_floor.any():
            raise ValueError(f"{scene_source}: camera {camera.name!r} does not see the floor (z = 0) at all "
                             f"(position {list(camera.position)}, look_at {list(camera.look_at)}); "
                             "point it at the floor")
        if not view.in_image.any():
            logger.warning("%s: camera %r sees the floor but none of the projected image", scene_source, camera.name)
    return views


def _worker_count(options: RenderOptions, cameras: int) -> int:
    return options.threads or max(1, cameras)


class _CameraRenderer:
    """Frames of one camera: warped contents cached, blended, noised, encoded."""

    def __init__(self, camera: Camera, clock: CameraClock, sampler: CameraSampler, response: CameraResponse,
                 noise: SensorNoise, writer: Any, atlases: AtlasStore, timeline: ProjectionTimeline,
                 progress: Any, people: PeopleInView | None = None) -> None:
        self.camera = camera
        self.people = people
        self.clock = clock
        self.sampler = sampler
        self.response = response
        self.noise = noise
        self.writer = writer
        self.atlases = atlases
        self.progress = progress
        rows = camera.resolution[1]
        self.weights = [timeline.row_weights(clock.exposure_start(frame), clock.exposure_s, clock.readout_s, rows)
                        for frame in range(clock.frame_count)]
        self.starts = clock.exposure_start(np.arange(clock.frame_count))
        self.dropped = frozenset(clock.dropped)
        self.exposure = ExposureControl(camera.auto_exposure, camera.fps, response.photometric.gamma)
        self.gains: list[float] = []
        self.cache: OrderedDict[ContentKey, list] = OrderedDict()

    def keys(self, frames: range) -> set[ContentKey]:
        return {key for frame in frames for key in self.weights[frame]}

    def render(self, frames: range) -> None:
        for frame in frames:
            image = self.noise.quantise(self._frame(frame), self.exposure.encoded_scale)
            if frame not in self.dropped:
                self.writer.write(image)
                self.gains.append(self.exposure.gain)
            # A dropped frame was still exposed: the camera meters on it.
            self.exposure.meter(image)
            self.progress.update(1)

    def _frame(self, frame: int) -> np.ndarray:
        """Display-encoded frame, with the people in the room at mid-exposure."""
        weights = self.weights[frame]
        if self.people is not None:
            time_s = float(self.starts[frame]) + 0.5 * self.clock.exposure_s
            occluded = self.people.apply(self._irradiance(weights), self.response.ambient_gain, time_s, weights)
            if occluded is not None:
                return self.response.encode(occluded)
        return self._encoded(weights)

    def _encoded(self, weights: dict[ContentKey, float | np.ndarray]) -> np.ndarray:
        """Display-encoded frame: one content's cached values, or a blend in irradiance
        (per row where a rolling shutter's rows saw different contents)."""
        if len(weights) == 1:
            entry = self._entry(next(iter(weights)))
            if entry[1] is None:
                entry[1] = self.response.encode(entry[0])
            return entry[1]
        return self.response.encode(self._irradiance(weights))

    def _irradiance(self, weights: dict[ContentKey, float | np.ndarray]) -> np.ndarray:
        """Irradiance of a frame (a cached array when one content fills it: not to be
        modified)."""
        import cv2

        if len(weights) == 1:
            return self._entry(next(iter(weights)))[0]
        irradiance = None
        for key, weight in weights.items():
            part = self._entry(key)[0]
            if isinstance(weight, np.ndarray):
                weighted = part * weight
                irradiance = weighted if irradiance is None else cv2.add(irradiance, weighted)
            else:
                irradiance = part * np.float32(weight) if irradiance is None else cv2.scaleAdd(
                    part, weight, irradiance)
        return irradiance

    def _entry(self, key: ContentKey) -> list:
        """``[irradiance, encoded or None]`` of a content, warped on first use."""
        entry = self.cache.get(key)
        if entry is None:
            light = self.sampler.sample(self.atlases.get(key))
            entry = [self.response.irradiance(light), None]
            self.cache[key] = entry
            patterns = [k for k in self.cache if k[0] != "flat"]
            if len(patterns) > CAMERA_CACHE_SIZE:
                del self.cache[patterns[0]]
        else:
            self.cache.move_to_end(key)
        return entry


def _atlas_layout(scene: Scene, views: dict[str, FloorView], options: RenderOptions) -> AtlasLayout:
    """One layout for all cameras, deep enough for the blurriest sample of any."""
    blur_samples = scene.photometric.blur_px * options.supersample
    levels = max(pyramid_levels_needed(view, blur_samples) for view in views.values())
    return AtlasLayout.for_projector(scene.projector.resolution, levels)


def _noise_generators(seed: int, count: int) -> list[np.random.Generator]:
    """Independent noise streams, one per camera, from one seed."""
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(count)]


def camera_model(
    camera: Camera, view: FloorView, layout: AtlasLayout, scene: Scene, options: RenderOptions,
    rng: np.random.Generator,
) -> tuple[CameraSampler, CameraResponse, SensorNoise]:
    """Sampler, photometric response (the floor's albedo included) and sensor noise of one camera."""
    width, height = camera.resolution
    photometric = scene.photometric
    sampler = CameraSampler.from_view(view, layout, camera.resolution, options.supersample, photometric.blur_px)
    noise = SensorNoise(photometric.noise_std, (height, width), rng, fresh=options.fresh_noise)
    return sampler, CameraResponse.for_camera(camera, photometric, _albedo(scene.floor, view, camera)), noise


def _albedo(floor: Floor, view: FloorView, camera: Camera) -> np.ndarray | None:
    """The albedo per camera pixel (samples averaged): the floor's texture, and the
    boxes' reflectance where they stand; None for a plain floor without boxes."""
    import cv2

    from calibproj.simulate.boxes import FLOOR

    if floor.texture is None and view.reflectance is None:
        return None
    albedo = np.ones(view.floor_x.shape, dtype=np.float32)
    if floor.texture is not None:
        textured = floor_albedo(floor.texture, view.floor_x, view.floor_y, view.floor_footprint)
        albedo = textured if view.surface is None else np.where(view.surface == FLOOR, textured, 1.0)
    if view.reflectance is not None:
        albedo = albedo * view.reflectance
    albedo = np.asarray(albedo, dtype=np.float32)
    if albedo.shape[::-1] != tuple(camera.resolution):
        albedo = cv2.resize(albedo, camera.resolution, interpolation=cv2.INTER_AREA)
    return albedo


def _people_in_view(scene: Scene, view: FloorView, camera: Camera, sequence: Any) -> PeopleInView | None:
    """The scene's people as ``camera`` sees them, or None in an empty room."""
    import cv2

    from calibproj.simulate.timeline import content_image

    if not scene.people:
        return None
    floor = [view.floor_x, view.floor_y]
    if view.floor_x.shape[::-1] != tuple(camera.resolution):
        floor = [cv2.resize(values, camera.resolution, interpolation=cv2.INTER_AREA) for values in floor]
    photometric = scene.photometric
    projector = scene.projector
    light = ProjectorLight(np.asarray(projector.position, dtype=float), projector.K, projector.R, projector.t,
                           tuple(projector.resolution), lambda key: content_image(sequence, key))
    return PeopleInView(scene.people, camera.position, light, floor[0], floor[1],
                        vignetting_gain(camera, photometric.vignetting), photometric.ambient, photometric.contrast)


def _render_all(scene: Scene, sequence: Any, timeline: ProjectionTimeline, clocks: dict[str, CameraClock],
                views: dict[str, FloorView], folder: Path, seed: int, options: RenderOptions,
                progress: bool) -> dict[str, CameraVideo]:
    from calibproj.common.progress import progress_bar
    from calibproj.sequence.video import GreyVideoWriter

    layout = _atlas_layout(scene, views, options)
    generators = _noise_generators(seed, len(scene.cameras))
    renderers: list[_CameraRenderer] = []
    with AtlasStore(sequence, layout) as atlases, \
            ThreadPoolExecutor(max_workers=_worker_count(options, len(scene.cameras)),
                               thread_name_prefix="camera") as camera_pool:
        try:
            for index, camera in enumerate(scene.cameras):
                view = views.pop(camera.name)
                model = camera_model(camera, view, layout, scene, options, generators[index])
                people = _people_in_view(scene, view, camera, sequence)
                clock = clocks[camera.name]
                timed = bool(clock.jitter_s or clock.dropped)
                writer = GreyVideoWriter(folder / f"{camera.name}.mp4", camera.resolution, camera.fps,
                                         crf=options.crf if camera.crf is None else camera.crf,
                                         preset=options.preset,
                                         timestamps_s=clock.timestamps() if timed else None)
                bar = progress_bar(clocks[camera.name].frame_count, f"render {camera.name}", enabled=progress,
                                   position=index)
                renderers.append(_CameraRenderer(camera, clocks[camera.name], *model, writer, atlases, timeline, bar,
                                                 people))
            _run_chunks(renderers, atlases, camera_pool, options.chunk_s)
        except BaseException:
            for renderer in renderers:
                renderer.writer.abort()
                renderer.progress.close()
            raise
    videos = {}
    for renderer in renderers:
        renderer.writer.close()
        renderer.progress.close()
        camera = renderer.camera
        path = renderer.writer.path
        gains = tuple(renderer.gains) if camera.auto_exposure is not None else ()
        videos[camera.name] = CameraVideo(path, camera.resolution, camera.fps, len(renderer.clock.recorded),
                                          path.stat().st_size, gains)
    return videos


def _run_chunks(renderers: list[_CameraRenderer], atlases: AtlasStore, pool: ThreadPoolExecutor,
                chunk_s: float) -> None:
    """Render all cameras chunk by chunk; the next chunk's contents are drawn meanwhile."""
    first = min(float(renderer.starts[0]) for renderer in renderers)
    last = max(float(renderer.starts[-1]) for renderer in renderers)
    chunk_count = int((last - first) // chunk_s) + 1
    boundaries = first + chunk_s * np.arange(chunk_count + 1)
    boundaries[-1] = math.inf
    ranges = [_frame_ranges(renderer.starts, boundaries) for renderer in renderers]

    def chunk_keys(chunk: int) -> set[ContentKey]:
        if chunk >= chunk_count:
            return set()
        return set().union(*(renderer.keys(frames[chunk]) for renderer, frames in zip(renderers, ranges)))

    upcoming = chunk_keys(0)
    atlases.prefetch(upcoming)
    for chunk in range(chunk_count):
        upcoming = chunk_keys(chunk + 1)
        atlases.prefetch(upcoming)
        futures = [pool.submit(renderer.render, frames[chunk]) for renderer, frames in zip(renderers, ranges)]
        # Let every camera finish its chunk before an error stops the others' encoders.
        wait(futures)
        for future in futures:
            future.result()
        atlases.retain(upcoming)


def _frame_ranges(starts: np.ndarray, boundaries: np.ndarray) -> list[range]:
    """Frames whose exposure starts in each chunk ``[boundaries[i], boundaries[i + 1])``."""
    edges = np.searchsorted(starts, boundaries, side="left")
    return [range(int(edges[i]), int(edges[i + 1])) for i in range(len(boundaries) - 1)]
