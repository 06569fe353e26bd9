"""Mistakes in the inputs of a run that can be seen before the ingest, each reported in
one line naming what is on both sides, before any video is decoded and before a results
folder is started:

- fewer than two cameras (a calibration relates cameras to each other);
- the projector's own video among the camera videos (``projection.mp4``, whatever its
  name: recognised by its frame size, frame rate, length and content);
- videos and intrinsics files whose names do not match (each video is named after its
  camera's intrinsics file), with the likely pairs suggested.
"""

from __future__ import annotations

import difflib
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

# Mean absolute difference (grey levels, 0-255) under which a decoded frame is the
# projector's own image of the same pattern: compression leaves a few levels, a camera
# filming the projection differs by tens (perspective, blur, light, texture).
PROJECTOR_FRAME_DIFFERENCE = 12.0
# How many frames the length of the projector's video may differ from the sequence's.
PROJECTOR_LENGTH_FRAMES = 2
# Names at least this alike (difflib ratio) are suggested as meant for each other.
NAME_SIMILARITY = 0.5


def check_videos(folder: Path, sequence: Any, intrinsics: Any, earlier: Iterable[str] | None = ()) -> None:
    """Every check of this module on a folder of camera videos: the projector's video
    among them (with ``sequence``: a ``Sequence`` or its file), their names against the
    intrinsics' (``intrinsics``: a folder or a mapping; None skips it), and, unless
    ``earlier`` is None (a check of stored cameras), at least two cameras with the
    ``earlier`` ones merged in. A folder without videos is left to the ingest to report."""
    from calibproj.ingest.videos import VIDEO_SUFFIXES, video_paths
    from calibproj.sequence.sequence import Sequence

    if not folder.is_dir() or not any(p.suffix.lower() in VIDEO_SUFFIXES for p in folder.iterdir()):
        return
    videos = video_paths(folder)
    if sequence is not None:
        check_no_projector_video(videos, sequence if isinstance(sequence, Sequence) else Sequence.load(sequence))
    if earlier is not None:
        check_camera_count(folder, list(videos), earlier)
    check_intrinsics_names(folder, list(videos), intrinsics)


def check_camera_count(folder: Path, names: list[str], earlier: Iterable[str] = ()) -> None:
    """ValueError unless the videos (with the cameras of earlier observations merged in)
    give at least two cameras."""
    cameras = set(names) | set(earlier)
    if len(cameras) >= 2:
        return
    found = ", ".join(_video_file_names(folder, names)) or "none"
    count = "one camera video" if len(names) == 1 else f"{len(names)} camera videos"
    raise ValueError(f"{folder}: {count} ({found}); a calibration needs two or more cameras that see the "
                     f"projection together")


def check_no_projector_video(videos: Mapping[str, Path], sequence: Any) -> None:
    """ValueError when one of the videos is the projection itself rather than a camera's
    recording of it (a copy of ``projection.mp4``, whatever its name)."""
    for name, path in videos.items():
        if is_projector_video(path, sequence):
            raise ValueError(f"{path}: is the projector's video of the sequence, not a camera's recording of it; "
                             f"take it out of the videos folder (camera {name!r} would be the projector itself)")


def is_projector_video(path: str | os.PathLike, sequence: Any) -> bool:
    """Whether the video at ``path`` is ``sequence``'s own projection video: same frame
    size, frame rate and length, and a pattern frame equal to the pattern's image."""
    import cv2

    capture = cv2.VideoCapture(str(path))
    try:
        if not capture.isOpened():
            return False
        size = (int(capture.get(cv2.CAP_PROP_FRAME_WIDTH)), int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        fps = capture.get(cv2.CAP_PROP_FPS)
        frames = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        if size != tuple(sequence.projector) or not fps or abs(fps - sequence.fps) > 1e-3 * sequence.fps:
            return False
        if abs(frames - sequence.frame_count) > PROJECTOR_LENGTH_FRAMES or not sequence.patterns:
            return False
        pattern = sequence.patterns[0]
        capture.set(cv2.CAP_PROP_POS_FRAMES, (pattern.first_frame + pattern.last_frame) // 2)
        ok, frame = capture.read()
    finally:
        capture.release()
    if not ok or frame is None:
        return False
    grey = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
    expected = np.asarray(sequence.pattern_image(0), dtype=np.float32)
    if grey.shape != expected.shape:
        return False
    return float(np.mean(np.abs(grey.astype(np.float32) - expected))) < PROJECTOR_FRAME_DIFFERENCE


def check_intrinsics_names(folder: Path, names: list[str], intrinsics: Any) -> None:
    """ValueError when the videos' names and the intrinsics' names do not match: no video
    has intrinsics, or some videos have none while some intrinsics match no video (then
    they were surely meant for each other). A video without intrinsics while every
    intrinsics file has its video is left to fail alone."""
    available = _intrinsics_names(intrinsics)
    if available is None:
        return
    missing = [name for name in names if name not in available]
    unused = sorted(set(available) - set(names))
    if not missing or (len(missing) < len(names) and not unused):
        return
    where = intrinsics if isinstance(intrinsics, (str, os.PathLike)) else "the intrinsics given"
    videos = _video_file_names(folder, missing)
    files = _file_names(available, unused)
    renames = _likely_renames(folder, available, missing, unused)
    hint = f" (rename {', '.join(renames)}?)" if renames else ""
    if not unused:
        raise ValueError(f"{folder}: no video has intrinsics in {where} ({', '.join(videos)} have none); "
                         f"each video is named after its camera's intrinsics file")
    have = "has" if len(videos) == 1 else "have"
    match = "matches" if len(files) == 1 else "match"
    raise ValueError(f"{', '.join(videos)} in {folder} {have} no intrinsics in {where}, whose "
                     f"{', '.join(files)} {match} no video; each video is named after its camera's intrinsics "
                     f"file{hint}")


def _intrinsics_names(intrinsics: Any) -> dict[str, Any] | None:
    """Camera name -> its intrinsics entry, or None when they cannot be listed (the run
    reports that itself)."""
    from calibproj.formats.intrinsics import intrinsics_files_in
    from calibproj.formats.jsonio import FormatError

    if intrinsics is None:
        return None
    if isinstance(intrinsics, Mapping):
        return dict(intrinsics)
    try:
        return intrinsics_files_in(intrinsics)
    except FormatError:
        return None


def _likely_renames(folder: Path, available: Mapping[str, Any], videos: list[str], unused: list[str]) -> list[str]:
    """Renames that would pair them: a single video to the single unused intrinsics'
    name; else each unused intrinsics file to the name of the video it is most alike
    (the videos name the cameras in every output)."""
    if len(videos) == 1 and len(unused) == 1:
        video = _video_file_names(folder, videos)[0]
        return [f"{video} to {unused[0]}{Path(video).suffix}"]
    renames = []
    for name in unused:
        close = difflib.get_close_matches(name, videos, n=1, cutoff=NAME_SIMILARITY)
        if close:
            file = _file_names(available, [name])[0]
            renames.append(f"{file} to {close[0]}{Path(file).suffix}")
    return renames


def _video_file_names(folder: Path, names: Iterable[str]) -> list[str]:
    from calibproj.ingest.videos import VIDEO_SUFFIXES

    wanted = set(names)
    if not folder.is_dir():
        return sorted(wanted)
    found = sorted(path.name for path in folder.iterdir()
                   if path.is_file() and path.suffix.lower() in VIDEO_SUFFIXES and path.stem in wanted)
    return found or sorted(wanted)


def _file_names(available: Mapping[str, Any], names: list[str]) -> list[str]:
    """The intrinsics files of the named cameras (a mapping's entries are named by camera)."""
    out = []
    for name in names:
        files = available.get(name)
        out += [Path(file).name for file in files] if isinstance(files, list) else [name]
    return out
