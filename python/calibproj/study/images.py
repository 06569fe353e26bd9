"""One image condition of the marker study: a camera looking straight down at one
projected array, rendered (``render_stills``), its markers detected, and compared with
the rendering's truth.

The marker side in the image is set by the camera's focal length; blur, sensor noise,
room light and projector contrast by the scene's photometry. Centres are measured as a
calibration gets them: the detector's corners refined by the ingest's straight-edge fit,
and the time per frame includes that fit. A marker counts as
visible when its four corners lie inside the image; found when detected with its id;
a detection whose id the array does not show, or farther than ``FALSE_PX`` from its
true centre, is a false detection.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

CAMERA_HEIGHT_M = 2.5
IMAGE_SIZE = (1280, 720)
# A detection this far from its marker's true centre is a false one (markers are much
# farther apart).
FALSE_PX = 3.0
# Samples per pixel along each axis of the study's images: with one, the rendered edges
# fall on the pixel grid's phase and bias centres by up to 0.05 px, as much as the
# detectors' own error at 20-30 px.
SUPERSAMPLE = 2
# Projector pixels of a scale-1 marker and the array grid of the study's sequence.
MARKER_PX = 80
GRID = (4, 8)


@dataclass(frozen=True)
class ImageCondition:
    """What one image of the study is made under.

    Attributes:
        family: marker family spec (``aruco:4X4_50``, ``apriltag:tag36h11``, ...).
        sweep: which sweep it belongs to (``side``, ``blur``, ``noise``, ``light``).
        side_px: marker side in the image, pixels.
        blur_px: optical blur sigma, pixels.
        noise_std: sensor noise, grey levels.
        ambient, contrast: room light and projector contrast, fractions of full scale.
        seed: noise seed.
    """

    family: str
    sweep: str
    side_px: float
    blur_px: float = 0.7
    noise_std: float = 2.0
    ambient: float = 0.05
    contrast: float = 0.8
    seed: int = 0


def measure_image(condition: ImageCondition) -> dict[str, Any]:
    """Detection rate, centre error (RMS and worst, px), false detections and detection
    time (ms) of one rendered image; a dict with the condition's fields."""
    from calibproj.sequence.markers import MarkerDetector, family_info, marker_centres
    from calibproj.simulate.geometric import marker_corners_on_floor, project_points
    from calibproj.simulate.render import RenderOptions, render_stills

    sequence = study_sequence(condition.family)
    scene = study_scene(condition)
    options = RenderOptions(supersample=SUPERSAMPLE)
    image = render_stills(scene, sequence, 0, seed=condition.seed, options=options)["study"]
    corners = marker_corners_on_floor(scene, sequence.layout)[:, 0]  # array 0, its one scale
    projected = project_points(scene.cameras[0], corners.reshape(-1, 3)).distorted.reshape(-1, 4, 2)
    width, height = IMAGE_SIZE
    with np.errstate(invalid="ignore"):  # NaN: behind the camera
        visible = np.all((projected >= 0) & (projected <= [width - 1, height - 1]), axis=(1, 2))
    shown = sequence.markers_shown(0)
    truth = {int(i): c for i, c, v in zip(shown, marker_centres(projected), visible) if v}
    detector = MarkerDetector(condition.family, inverted=True, corner_refinement="none")
    started = time.perf_counter()
    ids, raw_corners = detector.detect(image)
    ids, found_corners = _refined_as_the_ingest_does(image, scene.cameras[0], ids, raw_corners,
                                                     family_info(condition.family).quad_cells)
    seconds = time.perf_counter() - started
    errors, false = [], 0
    for marker, centre in zip(ids.tolist(), marker_centres(found_corners)):
        expected = truth.get(int(marker))
        error = None if expected is None else float(np.hypot(*(centre - expected)))
        if error is None and int(marker) in shown.tolist():
            continue  # a marker of the array cut by the image border: neither counted nor false
        if error is None or error > FALSE_PX:
            false += 1
            continue
        errors.append(error)
    return {**asdict(condition), "visible": len(truth), "found": len(errors), "false": false,
            "rate": len(errors) / len(truth) if truth else float("nan"),
            "centre_rms_px": float(np.sqrt(np.mean(np.square(errors)))) if errors else float("nan"),
            "centre_max_px": float(max(errors)) if errors else float("nan"),
            "ms": 1e3 * seconds}


def _refined_as_the_ingest_does(image: np.ndarray, camera: Any, ids: np.ndarray, corners: np.ndarray,
                                quad_cells: int) -> tuple[np.ndarray, np.ndarray]:
    """The detector's raw corners refined by the ingest's straight-edge fit (the centres
    a calibration uses); a marker whose edges cannot be fitted is dropped."""
    from calibproj import _core
    from calibproj.formats.intrinsics import Intrinsics

    gray = np.ascontiguousarray(image if image.ndim == 2 else image[..., 0])
    K = np.array([[camera.fx, 0.0, camera.cx], [0.0, camera.fy, camera.cy], [0.0, 0.0, 1.0]])
    pinhole = Intrinsics("study", None, K)
    kept_ids, kept = [], []
    for marker, quad in zip(ids.tolist(), corners):
        refined = _core.ingest.refine_undistorted_corners(gray, np.asarray(quad, dtype=float), pinhole, quad_cells)
        if refined is not None:
            kept_ids.append(marker)
            kept.append(refined)
    return np.array(kept_ids, dtype=int), np.array(kept, dtype=float).reshape(-1, 4, 2)


def study_sequence(family: str) -> Any:
    """One array of ``GRID`` markers at one scale, white on black."""
    from calibproj.sequence.builder import build_sequence

    return build_sequence(markers=family, arrays=1, scales=(1.0,), grid=GRID, marker_px=MARKER_PX)


def study_scene(condition: ImageCondition) -> Any:
    """The small room's projector and floor, one camera straight down at
    ``CAMERA_HEIGHT_M`` whose focal length gives markers of ``side_px``, and the
    condition's photometry."""
    from calibproj.simulate.scene import load_scene

    scene = load_scene("small", seed=condition.seed)
    projector = scene.projector
    side_m = MARKER_PX * projector.position[2] / projector.fx
    focal = condition.side_px * CAMERA_HEIGHT_M / side_m
    width, height = IMAGE_SIZE
    camera = replace(scene.cameras[0], name="study", position=(0.0, 0.0, CAMERA_HEIGHT_M), look_at=(0.0, 1e-3, 0.0),
                     resolution=IMAGE_SIZE, fx=focal, fy=focal, cx=(width - 1) / 2.0, cy=(height - 1) / 2.0,
                     dist=(0.0, 0.0, 0.0, 0.0, 0.0), readout_s=0.0, auto_exposure=None)
    photometric = replace(scene.photometric, blur_px=condition.blur_px, noise_std=condition.noise_std,
                          ambient=condition.ambient, contrast=condition.contrast, vignetting=0.0)
    return replace(scene, cameras=(camera,), photometric=photometric, people=())
