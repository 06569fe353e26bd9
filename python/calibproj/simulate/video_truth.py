"""Ground truth of a rendered simulation: the common ``truth.json`` plus what only
videos have (timing, image positions of the MSM centres, clean frames per pattern).

Extra fields of ``truth.json`` written here::

    "timing": {"clock": "...", "projector_fps": 30.0, "sequence_frames": 2376,
               "cameras": {name: {"fps", "start_offset_s", "exposure_s", "frame_count",
                                  "first_exposure_start_s", "fps_ratio", "recorded_frames",
                                  "dropped_frames": [slots], "jitter_s": [per slot, or empty],
                                  "readout_s", "gains": [per recorded frame, or empty]}}},
    "image_points": {name: {"ids": [...], "distorted": [[u, v], ...], "undistorted": [...]}},
    "clean_frames": {name: [[frames exposed wholly inside pattern 0], [... pattern 1], ...]}
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibproj.simulate.geometric import project_points
from calibproj.simulate.scene import Scene
from calibproj.simulate.timeline import CameraClock, ProjectionTimeline
from calibproj.simulate.truth import truth_document

CLOCK_DESCRIPTION = (
    "sequence clock: t = 0 when projector frame 0 comes on, frame k shows during "
    "[k / projector_fps, (k + 1) / projector_fps); camera frame j (slot j of its frame grid) exposes "
    "during [first_exposure_start_s + j / fps + jitter_s[j], ... + exposure_s); dropped frames are "
    "not in the video"
)


def msm_floor_points(scene: Scene, sequence: Any) -> tuple[np.ndarray, np.ndarray]:
    """Point ids (``array * markers_per_array + marker``) and positions of every MSM
    centre of a sequence: on the floor, or on a box standing in the projection."""
    from calibproj.simulate.geometric import projected_points

    centres = np.asarray(sequence.centres, dtype=float).reshape(-1, 2)
    return np.arange(len(centres)), projected_points(scene, centres)[0]


def timing_json(timeline: ProjectionTimeline, clocks: dict[str, CameraClock],
                gains: dict[str, tuple[float, ...]] | None = None) -> dict[str, Any]:
    cameras = {
        name: {
            "fps": clock.fps,
            "start_offset_s": clock.start_offset_s,
            "exposure_s": clock.exposure_s,
            "frame_count": clock.frame_count,
            "first_exposure_start_s": float(clock.exposure_start(0) - (clock.jitter_s[0] if clock.jitter_s else 0.0)),
            "fps_ratio": clock.fps / timeline.fps,
            "recorded_frames": int(len(clock.recorded)),
            "dropped_frames": list(clock.dropped),
            "jitter_s": list(clock.jitter_s),
            "readout_s": clock.readout_s,
            "gains": list((gains or {}).get(name, ())),
        }
        for name, clock in clocks.items()
    }
    return {"clock": CLOCK_DESCRIPTION, "projector_fps": timeline.fps, "sequence_frames": timeline.frame_count,
            "cameras": cameras}


def image_points_json(scene: Scene, ids: np.ndarray, xyz: np.ndarray) -> dict[str, Any]:
    """Per camera, the MSM centres inside its image (and not hidden by a box): ids,
    distorted and undistorted pixels."""
    from calibproj.simulate import boxes

    out = {}
    for camera in scene.cameras:
        seen = project_points(camera, xyz)
        visible = seen.visible
        if scene.boxes:
            visible = visible & ~boxes.hidden(camera.center, np.nan_to_num(xyz), scene.boxes)
        out[camera.name] = {
            "ids": ids[visible].tolist(),
            "distorted": seen.distorted[visible].tolist(),
            "undistorted": seen.undistorted[visible].tolist(),
        }
    return out


def clean_frames_json(sequence: Any, clocks: dict[str, CameraClock]) -> dict[str, list[list[int]]]:
    """Per camera and pattern, the frames whose whole exposure shows only that pattern."""
    fps = float(sequence.fps)
    out = {}
    for name, clock in clocks.items():
        out[name] = [
            clock.frames_inside(pattern.first_frame / fps, (pattern.last_frame + 1) / fps).tolist()
            for pattern in sequence.patterns
        ]
    return out


def video_truth_document(scene: Scene, sequence: Any, timeline: ProjectionTimeline,
                         clocks: dict[str, CameraClock], settings: dict[str, Any],
                         gains: dict[str, tuple[float, ...]] | None = None) -> dict[str, Any]:
    """Body of ``truth.json`` for a rendered simulation."""
    ids, xyz = msm_floor_points(scene, sequence)
    markers_per_array = int(np.asarray(sequence.centres).shape[1])
    extra = {
        "simulation": {"kind": "video", **settings},
        "timing": timing_json(timeline, clocks, gains),
        "image_points": image_points_json(scene, ids, xyz),
        "clean_frames": clean_frames_json(sequence, clocks),
    }
    return truth_document(scene, (ids, xyz), markers_per_array, None, extra)
