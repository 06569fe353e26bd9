"""Building a projection sequence from options, and writing it to disk.

Timeline (frames at the projector rate), every block a contiguous segment::

    white | black | start code | black | patterns | black | end code | black | white

The white and black blocks (``reference_frames`` each) give a decoder the brightness
of a full-on and a full-off projector next to each code; the black blocks also
separate the codes from the patterns.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibproj.sequence.codes import LightCode, code_pair
from calibproj.sequence.layout import MsmLayout
from calibproj.sequence.sequence import MarkerSystem, Pattern, Segment, Sequence
from calibproj.sequence.video import DEFAULT_CRF, DEFAULT_PRESET, GreyVideoWriter

log = logging.getLogger(__name__)

SEQUENCE_FILE = "sequence.json"
VIDEO_FILE = "projection.mp4"
PNG_DIR = "patterns"


def default_frames_per_pattern(fps: float, min_camera_fps: float) -> int:
    """Projector frames per pattern so that a camera at ``min_camera_fps`` always has
    at least one frame exposed entirely inside every pattern.

    Camera frames start every ``T = 1 / min_camera_fps`` and each exposes for at most
    ``T``. Whatever the phase, one of them lies wholly inside an interval of length
    ``D`` when ``D >= T + exposure``, i.e. ``D >= 2 T`` in the worst case. At 30 fps
    for a 25 fps camera: ``2 * 30 / 25 = 2.4``, so 3 frames (100 ms per pattern;
    700 patterns take 70 s, as in the paper).
    """
    if not fps > 0 or not min_camera_fps > 0:
        raise ValueError(f"frame rates must be positive, got projector {fps} and camera {min_camera_fps}")
    return max(1, math.ceil(2.0 * fps / min_camera_fps - 1e-9))


@dataclass(frozen=True)
class SequenceOptions:
    """Everything that defines a projection sequence, with the defaults of the paper.

    Attributes:
        markers: marker family spec (``aruco:<DICT>`` or ``apriltag:<family>``).
        grid: markers per array as ``(rows, cols)``; ids 0 .. rows * cols - 1.
        arrays: number of arrays, each shifted by its own sub-cell offset.
        scales: scale factors of every MSM (distinct, positive).
        marker_px: marker side at scale 1 in projector pixels, border included.
        margin_px: image edge to outermost centres; None keeps the largest scale inside.
        snap_to_pixels: snap centres by <= 0.5 px so that edges fall on pixel boundaries.
        projector: projector resolution ``(width, height)``.
        fps: projector frame rate.
        frames_per_pattern: frames each pattern is shown; None derives it from
            ``min_camera_fps`` (see :func:`default_frames_per_pattern`).
        min_camera_fps: slowest camera that must see every pattern in one clean frame.
        inverted: white markers on black (as projected in the paper).
        min_gap_modules: smallest gap between two markers of one pattern, in modules.
        omit_conflicting: leave out (and record) markers that would overlap another or
            leave the image at some scale, instead of raising ValueError.
        code_degree: light codes are m-sequences of ``2**code_degree - 1`` bits.
        code_frames_per_bit: frames per code bit; None uses the frames per pattern rule.
        reference_frames: frames of each white or black block around the codes.
    """

    markers: str = "aruco:4X4_50"
    grid: tuple[int, int] = (4, 8)
    arrays: int = 100
    scales: tuple[float, ...] = (1.0, 1.4, 2.0, 3.0, 4.0, 6.0, 8.0)
    marker_px: float = 24.0
    margin_px: float | None = None
    snap_to_pixels: bool = True
    projector: tuple[int, int] = (1920, 1080)
    fps: float = 30.0
    frames_per_pattern: int | None = None
    min_camera_fps: float = 25.0
    inverted: bool = True
    min_gap_modules: float = 0.5
    omit_conflicting: bool = False
    code_degree: int = 5
    code_frames_per_bit: int | None = None
    reference_frames: int = 15


def build_sequence(options: SequenceOptions | None = None, **overrides: Any) -> Sequence:
    """The sequence that ``options`` (updated with ``overrides``) describe, without
    writing anything. ValueError with a clear message for bad options."""
    options = _with_overrides(options, overrides)
    markers = _marker_system(options)
    layout = _layout(options)
    if layout.markers_per_array > markers.id_count:
        raise ValueError(f"a {options.grid[0]}x{options.grid[1]} grid needs {layout.markers_per_array} ids but "
                         f"{markers.spec} has only {markers.id_count}")
    omitted = _omissions(layout, markers, options)
    bits_frames = options.code_frames_per_bit or default_frames_per_pattern(options.fps, options.min_camera_fps)
    shown = [ShownPattern(array, scale_index, omitted[scale_index][array])
             for array in range(layout.arrays) for scale_index in range(len(layout.scales))]
    return assemble_sequence(markers, layout, layout.centres(), shown, fps=float(options.fps),
                             frames_per_pattern=_frames_per_pattern(options), code_degree=options.code_degree,
                             code_frames_per_bit=bits_frames, reference_frames=options.reference_frames,
                             min_gap_modules=options.min_gap_modules)


@dataclass(frozen=True)
class ShownPattern:
    """One pattern to show: array ``array`` at the layout's scale ``scale_index``,
    without the markers in ``omitted``."""

    array: int
    scale_index: int
    omitted: tuple[int, ...] = ()


def assemble_sequence(markers: MarkerSystem, layout: MsmLayout, centres: np.ndarray, shown: list[ShownPattern], *,
                      fps: float, frames_per_pattern: int, code_degree: int, code_frames_per_bit: int,
                      reference_frames: int, min_gap_modules: float) -> Sequence:
    """The sequence that shows the patterns ``shown`` in order, framed by the reference
    frames and light codes of the module docstring's timeline (checked: ValueError)."""
    if code_frames_per_bit < 1 or reference_frames < 1:
        raise ValueError("code_frames_per_bit and reference_frames must be at least 1")
    if not shown:
        raise ValueError("a sequence needs at least one pattern")
    start_bits, end_bits = code_pair(code_degree)
    timeline = _Timeline()
    timeline.add("white", reference_frames)
    timeline.add("black", reference_frames)
    start = LightCode(start_bits, code_frames_per_bit, timeline.add("start_code", len(start_bits) * code_frames_per_bit))
    timeline.add("black", reference_frames)
    first_pattern_frame = timeline.add("patterns", len(shown) * frames_per_pattern)
    timeline.add("black", reference_frames)
    end = LightCode(end_bits, code_frames_per_bit, timeline.add("end_code", len(end_bits) * code_frames_per_bit))
    timeline.add("black", reference_frames)
    timeline.add("white", reference_frames)
    patterns = []
    for item in shown:
        first = first_pattern_frame + len(patterns) * frames_per_pattern
        scale = layout.scales[item.scale_index]
        patterns.append(Pattern(item.array, item.scale_index, scale, layout.marker_side(scale), first,
                                first + frames_per_pattern - 1, tuple(item.omitted)))
    return Sequence(markers=markers, projector=layout.projector, fps=float(fps), grid=layout.grid,
                    scales=layout.scales, marker_px=layout.marker_px, margin_px=layout.margin,
                    snap_to_pixels=layout.snap_to_pixels, min_gap_modules=min_gap_modules,
                    frames_per_pattern=frames_per_pattern, centres=centres, patterns=patterns,
                    segments=timeline.segments, start_code=start, end_code=end)


def overhead_frames(code_degree: int, code_frames_per_bit: int, reference_frames: int) -> int:
    """Frames of a sequence besides its patterns: six reference blocks and two codes."""
    return 6 * reference_frames + 2 * (2 ** code_degree - 1) * code_frames_per_bit


def overhead_seconds(sequence: Sequence, code_degree: int | None = None,
                     reference_frames: int | None = None) -> float:
    """Seconds of a sequence with ``sequence``'s timing besides its patterns (reference
    frames and light codes), with its codes and reference blocks unless others are given."""
    start = sequence.start_code
    degree = _code_degree(start) if code_degree is None else code_degree
    blocks = sequence.segments[0].frame_count if reference_frames is None else reference_frames
    return overhead_frames(degree, start.frames_per_bit, blocks) / sequence.fps


def pattern_budget(sequence: Sequence, max_seconds: float, code_degree: int | None = None,
                   reference_frames: int | None = None) -> int:
    """Patterns a sequence with ``sequence``'s timing (and its codes and reference blocks,
    unless others are given) can show within ``max_seconds`` (0 when the rest alone
    takes longer)."""
    overhead = overhead_seconds(sequence, code_degree, reference_frames)
    frames = math.floor(max_seconds * sequence.fps + 1e-9) - round(overhead * sequence.fps)
    return max(0, frames // sequence.frames_per_pattern)


def reassembled(sequence: Sequence, layout: MsmLayout, centres: np.ndarray, shown: list[ShownPattern], *,
                code_degree: int | None = None, reference_frames: int | None = None) -> Sequence:
    """A sequence of ``sequence``'s markers, frame rate and timing that shows ``shown`` of
    ``layout`` and ``centres`` (a densified or check projection), with its codes and
    reference blocks unless others are given."""
    start = sequence.start_code
    return assemble_sequence(sequence.markers, layout, centres, shown, fps=sequence.fps,
                             frames_per_pattern=sequence.frames_per_pattern,
                             code_degree=_code_degree(start) if code_degree is None else code_degree,
                             code_frames_per_bit=start.frames_per_bit,
                             reference_frames=sequence.segments[0].frame_count if reference_frames is None
                             else reference_frames,
                             min_gap_modules=sequence.min_gap_modules)


def _code_degree(code: LightCode) -> int:
    return int(round(math.log2(len(code.bits) + 1)))


def generate(
    out_dir: str | os.PathLike,
    options: SequenceOptions | None = None,
    *,
    video: bool = True,
    png: bool = False,
    crf: int = DEFAULT_CRF,
    preset: str = DEFAULT_PRESET,
    progress: bool = False,
    **overrides: Any,
) -> Sequence:
    """Write a projection sequence to ``out_dir``: ``projection.mp4`` and ``sequence.json``.

    Args:
        out_dir: output folder (created if needed).
        options: :class:`SequenceOptions`; keyword ``overrides`` replace its fields,
            e.g. ``generate("seq", markers="apriltag:tag36h11", arrays=10)``.
        video: write ``projection.mp4`` (H.264, yuv420p, via the ffmpeg program).
        png: also write every pattern as ``patterns/pattern_<index>.png`` (all frames
            of a pattern are identical).
        crf: x264 constant-rate factor (lower is better quality, larger file).
        preset: x264 preset.
        progress: show a progress bar while writing frames.

    Returns:
        The :class:`Sequence` written. ``sequence.json`` is written last, so its
        presence means the video is complete.
    """
    sequence = build_sequence(options, **overrides)
    write_sequence(out_dir, sequence, video=video, png=png, crf=crf, preset=preset, progress=progress)
    return sequence


def write_sequence(out_dir: str | os.PathLike, sequence: Sequence, *, video: bool = True, png: bool = False,
                   crf: int = DEFAULT_CRF, preset: str = DEFAULT_PRESET, progress: bool = False) -> None:
    """Write ``sequence`` to ``out_dir`` as :func:`generate` does (``sequence.json`` last)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if video:
        _write_video(sequence, out / VIDEO_FILE, crf, preset, progress)
    if png:
        _write_pngs(sequence, out / PNG_DIR)
    sequence.save(out / SEQUENCE_FILE)
    log.debug("wrote %s: %d frames (%.1f s), %d patterns, %d points", out, sequence.frame_count,
             sequence.duration_s, len(sequence.patterns), sequence.point_count)


class _Timeline:
    """Contiguous segments appended in order."""

    def __init__(self) -> None:
        self.segments: list[Segment] = []
        self.next_frame = 0

    def add(self, kind: str, frames: int) -> int:
        """Append ``frames`` frames of ``kind``; return the first frame."""
        first = self.next_frame
        self.segments.append(Segment(kind, first, first + frames - 1))
        self.next_frame += frames
        return first


def _with_overrides(options: SequenceOptions | None, overrides: dict[str, Any]) -> SequenceOptions:
    options = options or SequenceOptions()
    known = {f.name for f in dataclasses.fields(SequenceOptions)}
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise ValueError(f"unknown sequence option(s) {', '.join(unknown)} (choose from {', '.join(sorted(known))})")
    return dataclasses.replace(options, **overrides)


def _marker_system(options: SequenceOptions) -> MarkerSystem:
    return MarkerSystem(options.markers, bool(options.inverted))


def _layout(options: SequenceOptions) -> MsmLayout:
    scales = tuple(float(s) for s in options.scales)
    if len(set(scales)) != len(scales):
        raise ValueError(f"scales must be distinct, got {list(scales)}")
    if not options.min_gap_modules >= 0:
        raise ValueError(f"min_gap_modules must be non-negative, got {options.min_gap_modules}")
    return MsmLayout(projector=tuple(int(v) for v in options.projector), grid=tuple(int(v) for v in options.grid),
                     arrays=int(options.arrays), scales=scales, marker_px=float(options.marker_px),
                     margin_px=options.margin_px, snap_to_pixels=options.snap_to_pixels)


def _frames_per_pattern(options: SequenceOptions) -> int:
    if options.frames_per_pattern is None:
        return default_frames_per_pattern(options.fps, options.min_camera_fps)
    if options.frames_per_pattern < 1:
        raise ValueError(f"frames_per_pattern must be at least 1, got {options.frames_per_pattern}")
    return int(options.frames_per_pattern)


def _omissions(layout: MsmLayout, markers: MarkerSystem, options: SequenceOptions) -> list[list[tuple[int, ...]]]:
    """Per scale and array, the markers left out; ValueError naming the scale when
    markers conflict and ``omit_conflicting`` is off."""
    omitted = []
    for scale in layout.scales:
        side = layout.marker_side(scale)
        module = side / markers.grid_cells
        if module < 1.0:
            raise ValueError(f"at scale {scale:g} a {markers.grid_cells}-module marker of {side:.1f} px has "
                             f"{module:.2f} px modules; use a larger marker_px (at least {markers.grid_cells})")
        gap = options.min_gap_modules * module
        outside = layout.outside_image(side)
        close = layout.too_close(side, gap)
        if not options.omit_conflicting:
            _raise_on_conflict(layout, scale, side, gap, outside, close, options.min_gap_modules)
        omitted.append([_greedy_omissions(outside[a], close[a]) for a in range(layout.arrays)])
        skipped = sum(len(o) for o in omitted[-1])
        if skipped:
            log.warning("scale %g: %d of %d markers left out (overlap or outside the image)", scale, skipped,
                        layout.arrays * layout.markers_per_array)
    return omitted


def _raise_on_conflict(layout: MsmLayout, scale: float, side: float, gap: float, outside: np.ndarray,
                       close: np.ndarray, min_gap_modules: float) -> None:
    hint = "use a smaller marker_px, fewer or smaller scales, a smaller grid, or omit_conflicting"
    if outside.any():
        array, marker = (int(v) for v in np.argwhere(outside)[0])
        x, y = layout.centres()[array, marker]
        raise ValueError(
            f"at scale {scale:g} (marker side {side:.1f} px) {int(outside.sum())} markers leave the "
            f"{layout.projector[0]}x{layout.projector[1]} projector image, e.g. marker {marker} of array {array} "
            f"centred at ({x:.1f}, {y:.1f}); {hint} (or a larger margin_px)")
    if close.any():
        dx, dy = layout.marker_pitch()
        raise ValueError(
            f"at scale {scale:g} (marker side {side:.1f} px) markers of one array overlap or leave less than "
            f"{gap:.1f} px ({min_gap_modules:g} modules) between them: they are {dx:.1f} x {dy:.1f} px apart; "
            f"{hint}")


def _greedy_omissions(outside: np.ndarray, close: np.ndarray) -> tuple[int, ...]:
    """Markers to leave out of one array: those outside the image, then, in index
    order, every marker too close to one already kept."""
    kept: list[int] = []
    left_out = []
    for marker in range(len(outside)):
        if outside[marker] or close[marker, kept].any():
            left_out.append(marker)
        else:
            kept.append(marker)
    return tuple(left_out)


def _write_video(sequence: Sequence, path: Path, crf: int, preset: str, progress: bool) -> None:
    from calibproj.common.progress import progress_bar

    bar = progress_bar(sequence.frame_count, f"write {path.name}", enabled=progress)
    try:
        with GreyVideoWriter(path, sequence.projector, sequence.fps, crf=crf, preset=preset) as writer:
            for index in range(sequence.frame_count):
                writer.write(sequence.frame(index))
                bar.update(1)
    finally:
        bar.close()


def _write_pngs(sequence: Sequence, folder: Path) -> None:
    import cv2

    from calibproj.formats.jsonio import atomic_write_bytes

    for index in range(len(sequence.patterns)):
        ok, encoded = cv2.imencode(".png", sequence.pattern_image(index))
        if not ok:
            raise RuntimeError(f"could not encode pattern {index} as PNG")
        atomic_write_bytes(folder / f"pattern_{index:04d}.png", encoded.tobytes())
