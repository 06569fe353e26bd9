"""Marker families, marker images and single-image marker detection.

A marker family is named by a spec string: ``"aruco:<DICT>"`` for OpenCV's predefined
dictionaries (``aruco:4X4_50``, ``aruco:ARUCO_ORIGINAL``, ``aruco:APRILTAG_36h11``, ...)
or ``"apriltag:<family>"`` for libapriltag's families (``apriltag:tag36h11``,
``apriltag:tagStandard41h12``, ...); :func:`marker_families` lists them all.

Detection runs in the C++ core (OpenCV 4.6 ArUco or libapriltag). Both systems return
corners in OpenCV's pixel convention (centre of the top-left pixel at (0, 0)) and
OpenCV's order: clockwise from the top-left corner of the marker as
:func:`marker_bits` draws it. Options (keyword arguments of :class:`MarkerDetector`):

Common
    ``inverted`` (False): markers are white on black, as projected.
    ``corner_refinement`` ("edges"): "edges" fits a line to each edge and intersects
    them (unbiased under rotation and perspective), "subpix" runs cv::cornerSubPix
    with a window scaled to the marker, "none" keeps the detector's corners.
    Finer knobs of the refinement keep their C++ names (``window_fraction``,
    ``edge_search_fraction``, ``edge_passes``, ...; see ``corner_refinement.h``).
ArUco
    ``min_marker_perimeter_rate`` (0.01), ``max_marker_perimeter_rate`` (4.0),
    ``adaptive_thresh_win_size_min/max/step`` (3/23/10), ``adaptive_thresh_constant``
    (7; the most, see next), ``thresh_constant_contrast_share`` (0.035: the constant is
    this share of the image's contrast, its brightest 0.5 % above its median, so
    markers under room light are segmented; 0 keeps the fixed constant),
    ``min_thresh_constant`` (3: lower lets grout lines and stains through),
    ``error_correction_rate`` (0.6), ``perspective_remove_pixel_per_cell`` (8) and
    ``perspective_remove_ignored_margin_per_cell`` (0.3): bits are read from each
    module's centre, so markers whose white modules bloom into the black ones
    (saturation under automatic exposure) keep their ids (OpenCV's 4 and 0.13 lose
    most of them).
AprilTag
    ``quad_decimate`` (1.0), ``quad_sigma`` (0.0), ``nthreads`` (1), ``refine_edges``
    (True), ``decode_sharpening`` (0.25), ``max_hamming`` (2),
    ``min_white_black_diff`` (5).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from calibproj.sequence.raster import draw_cells

DEFAULT_MARKERS = "aruco:4X4_50"

_REFINEMENT_METHODS = ("none", "subpix", "edges")


def _core_detect() -> Any:
    """The C++ detection module, imported on first use so that ``import calibproj``
    stays light."""
    from calibproj._core import detect

    return detect


def marker_families() -> list[str]:
    """Every marker family spec this build accepts."""
    return list(_core_detect().family_specs())


def family_info(markers: str = DEFAULT_MARKERS) -> Any:
    """Describe a marker family (the core's ``MarkerFamilyInfo``: spec, system, name,
    id_count, grid_cells, quad_cells); ``ValueError`` naming the choices for an unknown one."""
    return _core_detect().family_info(markers)


def marker_bits(markers: str, marker_id: int) -> np.ndarray:
    """Cells of one marker as a square ``uint8`` array of 0 (black) and 1 (white).

    The grid is the marker as printed black on white, border included, quiet zone
    excluded (shape ``(grid_cells, grid_cells)``).
    """
    return _core_detect().marker_bits(markers, int(marker_id))


def render_marker(
    markers: str,
    marker_id: int,
    module_px: float = 10.0,
    inverted: bool = False,
    quiet_modules: float = 1.0,
) -> np.ndarray:
    """One marker as a ``uint8`` grey image with a quiet zone around it.

    The marker's centre is the image centre, also for a non-integer ``module_px``:
    cells are drawn by exact area coverage, so edges that fall inside a pixel give
    it a proportional grey level.

    Args:
        markers: family spec.
        marker_id: id to draw.
        module_px: side of one cell in pixels (> 0).
        inverted: white marker on black (as projected) instead of black on white.
        quiet_modules: width of the background margin in cells (>= 0).
    """
    if not module_px > 0:
        raise ValueError(f"module_px must be positive, got {module_px}")
    if not quiet_modules >= 0:
        raise ValueError(f"quiet_modules must be non-negative, got {quiet_modules}")
    bits = marker_bits(markers, marker_id).astype(np.float32)
    side_px = bits.shape[0] * module_px
    size = math.ceil(side_px + 2.0 * quiet_modules * module_px - 1e-9)
    canvas = np.ones((size, size), np.float32)
    centre = ((size - 1) / 2.0, (size - 1) / 2.0)
    draw_cells(canvas, bits, centre, side_px)
    image = np.rint(canvas * 255.0).astype(np.uint8)
    return 255 - image if inverted else image


def as_gray_image(image: Any) -> np.ndarray:
    """A contiguous 2-D ``uint8`` view of a grey, grey (H, W, 1), BGR or BGRA image."""
    import cv2

    array = np.asarray(image)
    if array.dtype != np.uint8:
        raise ValueError(f"expected an 8-bit (uint8) image, got dtype {array.dtype}")
    if array.ndim == 3 and array.shape[2] == 1:
        array = array[:, :, 0]
    elif array.ndim == 3 and array.shape[2] in (3, 4):
        code = cv2.COLOR_BGR2GRAY if array.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        array = cv2.cvtColor(np.ascontiguousarray(array), code)
    elif array.ndim != 2:
        raise ValueError(f"expected a grey (H, W) or colour (H, W, 3) image, got shape {array.shape}")
    return np.ascontiguousarray(array)


_NOT_OPTIONS = ("check", "refinement", "method")


def _set_options(target: Any, options: dict[str, Any]) -> dict[str, Any]:
    """Set every option that ``target`` has; return the others."""
    rest = {}
    for name, value in options.items():
        if hasattr(target, name) and not name.startswith("_") and name not in _NOT_OPTIONS:
            setattr(target, name, value)
        else:
            rest[name] = value
    return rest


def _option_names(*targets: Any) -> list[str]:
    names = {"corner_refinement"}
    for target in targets:
        names.update(n for n in dir(target) if not n.startswith("_") and n not in _NOT_OPTIONS)
    return sorted(names)


def _build_options(system: str, options: dict[str, Any]) -> tuple[Any, Any]:
    core = _core_detect()
    aruco, apriltag = core.ArucoOptions(), core.AprilTagOptions()
    own = aruco if system == "aruco" else apriltag
    refinement = own.refinement
    options = dict(options)
    method = options.pop("corner_refinement", None)
    if method is not None:
        if method not in _REFINEMENT_METHODS:
            choices = ", ".join(_REFINEMENT_METHODS)
            raise ValueError(f"corner_refinement: unknown method {method!r} (choose from {choices})")
        refinement.method = getattr(core.CornerRefinement, method)
    rest = _set_options(refinement, _set_options(own, options))
    if rest:
        raise ValueError(
            f"unknown {system} detection option(s) {', '.join(sorted(rest))} "
            f"(choose from {', '.join(_option_names(own, refinement))})"
        )
    own.refinement = refinement
    own.check()
    return aruco, apriltag


class MarkerDetector:
    """Detector of one marker family; build it once and call :meth:`detect` per image.

    AprilTag families build their decoding tables here (measured at max_hamming 2:
    0.03 s for tag36h11, 0.13 s for tagStandard41h12, 20 s for the 48,714 codes of
    tagStandard52h13), so reusing the detector matters when processing video.
    """

    def __init__(self, markers: str = DEFAULT_MARKERS, **options: Any) -> None:
        self.info = family_info(markers)
        aruco, apriltag = _build_options(self.info.system, options)
        self._detector = _core_detect().MarkerDetector(self.info.spec, aruco, apriltag)

    @property
    def markers(self) -> str:
        return self.info.spec

    def detect(self, image: Any) -> tuple[np.ndarray, np.ndarray]:
        """Markers in a grey or BGR ``uint8`` image.

        Returns:
            ``(ids, corners)``: ids ``(N,)`` int32 sorted ascending and corners
            ``(N, 4, 2)`` float64 (OpenCV convention and order).
        """
        return self._detector.detect(as_gray_image(image))


def detect_markers(image: Any, markers: str = DEFAULT_MARKERS, **options: Any) -> tuple[np.ndarray, np.ndarray]:
    """Detect the markers of one family in one grey or BGR ``uint8`` image.

    A one-shot convenience around :class:`MarkerDetector` (see the module docstring
    for ``options``). Returns ``(ids (N,), corners (N, 4, 2))``.
    """
    return MarkerDetector(markers, **options).detect(image)


def marker_centres(corners: np.ndarray) -> np.ndarray:
    """Centres ``(N, 2)`` of markers with corners ``(N, 4, 2)``: the intersection of the
    diagonals, the image of the marker's centre under any homography."""
    return _core_detect().marker_centres(np.asarray(corners, dtype=np.float64).reshape(-1, 4, 2))
