"""Marker families, marker images and single-image detection (C++ core through Python)."""

from __future__ import annotations

import numpy as np
import pytest

from calibproj import detect_markers
from calibproj.sequence.markers import (
    MarkerDetector,
    family_info,
    marker_bits,
    marker_centres,
    marker_families,
    render_marker,
)

# Families the brief names, one per kind of layout: ArUco, classic AprilTag, AprilTag
# with its border inside (data ring outside the detected square).
FAMILIES = ["aruco:4X4_50", "aruco:APRILTAG_36h11", "apriltag:tag36h11", "apriltag:tagStandard41h12"]


def render_warped(bits: np.ndarray, H: np.ndarray, shape: tuple[int, int], supersample: int = 8) -> np.ndarray:
    """Image of a cell grid mapped by ``H`` (grid coordinates in cells -> pixels) on a
    white background, each pixel the mean of supersample^2 point samples (a close
    approximation of exact area coverage; OpenCV's pixel convention)."""
    height, width = shape
    rows, cols = np.mgrid[0 : height * supersample, 0 : width * supersample].astype(np.float64)
    x = (cols + 0.5) / supersample - 0.5
    y = (rows + 0.5) / supersample - 0.5
    inverse = np.linalg.inv(H)
    w = inverse[2, 0] * x + inverse[2, 1] * y + inverse[2, 2]
    u = (inverse[0, 0] * x + inverse[0, 1] * y + inverse[0, 2]) / w
    v = (inverse[1, 0] * x + inverse[1, 1] * y + inverse[1, 2]) / w
    n = bits.shape[0]
    inside = (u >= 0) & (u < n) & (v >= 0) & (v < n)
    values = np.ones_like(u)
    values[inside] = bits[v[inside].astype(int), u[inside].astype(int)]
    image = values.reshape(height, supersample, width, supersample).mean(axis=(1, 3))
    return np.rint(image * 255).astype(np.uint8)


def apply_homography(H: np.ndarray, points: np.ndarray) -> np.ndarray:
    projected = np.c_[points, np.ones(len(points))] @ H.T
    return projected[:, :2] / projected[:, 2:]


def random_view(rng: np.random.Generator, cells: int, side_px: float, size: int) -> np.ndarray:
    """A homography from grid cells to pixels: rotation, shear and perspective around
    the image centre, the marker about ``side_px`` wide."""
    angle = rng.uniform(0, 2 * np.pi)
    scale = side_px / cells
    rotate = np.array([[scale * np.cos(angle), -scale * np.sin(angle), 0],
                       [scale * np.sin(angle), scale * np.cos(angle), 0], [0, 0, 1]])
    centre = np.array([[1, 0, -cells / 2], [0, 1, -cells / 2], [0, 0, 1]])
    perspective = np.array([[1, rng.uniform(-0.1, 0.1), 0], [0, 1, 0],
                            [rng.uniform(-0.3, 0.3) / side_px, rng.uniform(-0.3, 0.3) / side_px, 1]])
    shift = np.array([[1, 0, size / 2 + rng.uniform(-2, 2)], [0, 1, size / 2 + rng.uniform(-2, 2)], [0, 0, 1]])
    return shift @ perspective @ rotate @ centre


def quad_corners_in_cells(markers: str) -> np.ndarray:
    """Corners of the detected square in grid cells, OpenCV order (TL, TR, BR, BL)."""
    info = family_info(markers)
    low = (info.grid_cells - info.quad_cells) / 2
    high = low + info.quad_cells
    return np.array([[low, low], [high, low], [high, high], [low, high]])


# --------------------------------------------------------------------------- families


def test_every_documented_family_is_available():
    specs = marker_families()
    for name in ["4X4_50", "4X4_100", "4X4_250", "4X4_1000", "5X5_50", "6X6_250", "7X7_1000", "ARUCO_ORIGINAL",
                 "APRILTAG_16h5", "APRILTAG_25h9", "APRILTAG_36h10", "APRILTAG_36h11"]:
        assert f"aruco:{name}" in specs
    for name in ["tag36h11", "tag25h9", "tag16h5", "tagStandard41h12"]:
        assert f"apriltag:{name}" in specs


def test_family_info_and_canonical_spelling():
    info = family_info("ArUco:4x4_50")
    assert (info.spec, info.system, info.name, info.id_count) == ("aruco:4X4_50", "aruco", "4X4_50", 50)
    assert (info.grid_cells, info.quad_cells) == (6, 6)
    assert family_info("apriltag:tag36h11").id_count == 587
    assert (family_info("apriltag:tag36h11").grid_cells, family_info("apriltag:tag36h11").quad_cells) == (8, 8)
    standard = family_info("apriltag:tagstandard41h12")
    assert (standard.spec, standard.grid_cells, standard.quad_cells) == ("apriltag:tagStandard41h12", 9, 5)


@pytest.mark.parametrize("spec", ["aruco:4X4_51", "apriltag:tag99h9", "charuco:4X4_50", "4X4_50", ""])
def test_unknown_family_names_it_and_lists_the_choices(spec):
    with pytest.raises(ValueError, match="unknown marker family") as error:
        family_info(spec)
    assert spec in str(error.value)
    assert "aruco:4X4_50" in str(error.value) or "apriltag:tag36h11" in str(error.value)


def test_marker_bits_have_a_black_border():
    bits = marker_bits("aruco:4X4_50", 7)
    assert bits.shape == (6, 6) and bits.dtype == np.uint8
    assert set(np.unique(bits)) <= {0, 1}
    border = np.concatenate([bits[0], bits[-1], bits[:, 0], bits[:, -1]])
    assert not border.any()


def test_apriltag_grids_match_opencv_copies_of_the_same_tags():
    # libapriltag's rendering turned by 180 degrees is OpenCV's DICT_APRILTAG_36h11.
    for marker_id in (0, 1, 17, 586):
        np.testing.assert_array_equal(marker_bits("apriltag:tag36h11", marker_id),
                                      marker_bits("aruco:APRILTAG_36h11", marker_id))


def test_tag_standard41h12_has_its_border_inside():
    bits = marker_bits("apriltag:tagStandard41h12", 0)
    assert bits.shape == (9, 9)
    # The detected 5x5 square is white-edged (reversed border) around a black ring.
    ring = np.concatenate([bits[2, 2:7], bits[6, 2:7], bits[2:7, 2], bits[2:7, 6]])
    assert ring.all()
    inner_ring = np.concatenate([bits[1, 1:8], bits[7, 1:8], bits[1:8, 1], bits[1:8, 7]])
    assert not inner_ring.any()


@pytest.mark.parametrize("marker_id", [-1, 50])
def test_marker_id_out_of_range(marker_id):
    with pytest.raises(ValueError, match="out of range"):
        marker_bits("aruco:4X4_50", marker_id)


# ----------------------------------------------------------------------- rendering


def test_render_marker_keeps_the_centre_for_any_module_size():
    for module_px in (4.0, 3.3, 5.75):
        image = render_marker("aruco:4X4_50", 3, module_px=module_px)
        ids, corners = detect_markers(image, "aruco:4X4_50")
        assert ids.tolist() == [3]
        centre = (image.shape[1] - 1) / 2
        np.testing.assert_allclose(marker_centres(corners)[0], [centre, centre], atol=0.01)
        side = 6 * module_px
        np.testing.assert_allclose(corners[0, 0], [centre - side / 2, centre - side / 2], atol=0.02)


def test_render_marker_inverted_is_the_negative():
    normal = render_marker("apriltag:tag36h11", 5, module_px=3.5)
    inverted = render_marker("apriltag:tag36h11", 5, module_px=3.5, inverted=True)
    np.testing.assert_array_equal(inverted.astype(int), 255 - normal.astype(int))
    assert detect_markers(inverted, "apriltag:tag36h11")[0].size == 0
    assert detect_markers(inverted, "apriltag:tag36h11", inverted=True)[0].tolist() == [5]


def test_render_marker_rejects_bad_sizes():
    with pytest.raises(ValueError, match="module_px"):
        render_marker("aruco:4X4_50", 0, module_px=0)
    with pytest.raises(ValueError, match="quiet_modules"):
        render_marker("aruco:4X4_50", 0, quiet_modules=-1)


# ----------------------------------------------------------------------- detection


@pytest.mark.parametrize("markers", FAMILIES)
@pytest.mark.parametrize("inverted", [False, True])
def test_corners_under_a_known_homography(markers, inverted):
    """Measured on noise-free supersampled views with rotation and strong perspective
    (40 px markers): corner RMS ~0.01 px, centre RMS ~0.01 px with the default edge
    refinement (cv::cornerSubPix alone: ~0.2 px corners, ~0.07 px centres)."""
    rng = np.random.default_rng(7)
    info = family_info(markers)
    detector = MarkerDetector(markers, inverted=inverted)
    corner_errors, centre_errors = [], []
    for trial in range(4):
        marker_id = int(rng.integers(0, min(info.id_count, 30)))
        H = random_view(rng, info.grid_cells, 40.0, 96)
        image = render_warped(marker_bits(markers, marker_id), H, (96, 96))
        if inverted:
            image = 255 - image
        ids, corners = detector.detect(image)
        assert ids.tolist() == [marker_id], f"trial {trial}"
        truth = apply_homography(H, quad_corners_in_cells(markers))
        corner_errors.append(np.linalg.norm(corners[0] - truth, axis=1))
        true_centre = apply_homography(H, np.array([[info.grid_cells / 2, info.grid_cells / 2]]))[0]
        centre_errors.append(np.linalg.norm(marker_centres(corners)[0] - true_centre))
    assert np.sqrt(np.mean(np.square(corner_errors))) < 0.05
    assert max(centre_errors) < 0.06


def test_edge_refinement_beats_corner_subpix_on_rotated_views():
    rng = np.random.default_rng(3)
    errors = {"edges": [], "subpix": []}
    for _ in range(4):
        H = random_view(rng, 6, 48.0, 100)
        image = render_warped(marker_bits("aruco:4X4_50", 1), H, (100, 100))
        truth = apply_homography(H, quad_corners_in_cells("aruco:4X4_50"))
        for method in errors:
            _, corners = detect_markers(image, "aruco:4X4_50", corner_refinement=method)
            errors[method].append(np.linalg.norm(corners[0] - truth, axis=1))
    assert np.mean(errors["edges"]) < 0.5 * np.mean(errors["subpix"])


def test_apriltag_and_aruco_agree_on_the_same_image():
    rng = np.random.default_rng(11)
    H = random_view(rng, 8, 60.0, 140)
    image = render_warped(marker_bits("apriltag:tag36h11", 42), H, (140, 140))
    ids_april, corners_april = detect_markers(image, "apriltag:tag36h11")
    ids_aruco, corners_aruco = detect_markers(image, "aruco:APRILTAG_36h11")
    assert ids_april.tolist() == ids_aruco.tolist() == [42]
    np.testing.assert_allclose(corners_april, corners_aruco, atol=0.05)


def test_corners_follow_opencv_order_from_the_drawn_top_left():
    for markers in FAMILIES:
        image = render_marker(markers, 2, module_px=6.0, quiet_modules=2)
        _, corners = detect_markers(image, markers)
        top_left, top_right, bottom_right, bottom_left = corners[0]
        assert top_left[0] < top_right[0] and top_left[1] < bottom_left[1], markers
        assert bottom_right[0] > bottom_left[0] and bottom_right[1] > top_right[1], markers


def test_several_markers_sorted_by_id_and_bgr_input():
    tiles = [render_marker("aruco:5X5_100", marker_id, module_px=5) for marker_id in (9, 4, 30)]
    image = np.hstack(tiles)
    bgr = np.dstack([image] * 3)
    ids, corners = detect_markers(bgr, "aruco:5X5_100")
    assert ids.tolist() == [4, 9, 30]
    assert corners.shape == (3, 4, 2) and corners.dtype == np.float64


def test_no_marker_gives_empty_arrays():
    ids, corners = detect_markers(np.full((64, 80), 255, np.uint8), "apriltag:tagStandard41h12")
    assert ids.shape == (0,) and corners.shape == (0, 4, 2)


def test_odd_sized_and_strided_images_work():
    image = np.full((101, 77), 255, np.uint8)
    tile = render_marker("aruco:4X4_50", 0, module_px=7)
    image[10 : 10 + tile.shape[0], 5 : 5 + tile.shape[1]] = tile
    assert detect_markers(image, "aruco:4X4_50")[0].tolist() == [0]
    strided = np.full((101, 160), 255, np.uint8)[:, ::2]
    strided[10 : 10 + tile.shape[0], 5 : 5 + tile.shape[1]] = tile
    assert detect_markers(strided, "apriltag:tag36h11")[0].size == 0
    assert detect_markers(strided, "aruco:4X4_50")[0].tolist() == [0]


@pytest.mark.parametrize("markers", ["aruco:4X4_50", "apriltag:tag36h11"])
@pytest.mark.parametrize(
    "image, message",
    [
        (np.zeros((0, 0), np.uint8), "empty"),
        (np.zeros((3, 5), np.uint8), "too small"),
        (np.zeros((40, 40), np.float32), "uint8"),
        (np.zeros((40, 40), np.uint16), "uint8"),
        (np.zeros((40, 40, 2), np.uint8), "shape"),
        (np.zeros((4, 40, 40), np.uint8), "image"),
    ],
)
def test_bad_images_raise_value_error(markers, image, message):
    with pytest.raises(ValueError, match=message):
        detect_markers(image, markers)


def test_small_and_noisy_images_never_crash():
    rng = np.random.default_rng(2)
    detectors = [MarkerDetector("aruco:4X4_50"), MarkerDetector("apriltag:tagStandard41h12"),
                 MarkerDetector("apriltag:tag36h11", quad_decimate=2, nthreads=2)]
    for shape in [(8, 8), (9, 13), (13, 9), (31, 17), (97, 203)]:
        for image in (np.zeros(shape, np.uint8), rng.integers(0, 256, shape).astype(np.uint8)):
            for detector in detectors:
                detector.detect(image)
    # libapriltag reads out of bounds when decimation leaves under 3 px per side.
    with pytest.raises(ValueError, match="too small for quad_decimate 4"):
        detect_markers(np.zeros((8, 300), np.uint8), "apriltag:tag36h11", quad_decimate=4)


def test_unknown_and_bad_options():
    with pytest.raises(ValueError, match="unknown aruco detection option.*quad_decimate"):
        MarkerDetector("aruco:4X4_50", quad_decimate=2)
    with pytest.raises(ValueError, match="corner_refinement"):
        MarkerDetector("aruco:4X4_50", corner_refinement="magic")
    with pytest.raises(ValueError, match="quad_decimate"):
        MarkerDetector("apriltag:tag36h11", quad_decimate=0.5)
    with pytest.raises(ValueError, match="window_min_px"):
        MarkerDetector("apriltag:tag36h11", window_min_px=0)


def test_marker_centres_is_the_diagonal_intersection():
    rng = np.random.default_rng(5)
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    for _ in range(5):
        H = random_view(rng, 1, 50.0, 200)
        corners = apply_homography(H, square)[None]
        expected = apply_homography(H, np.array([[0.5, 0.5]]))
        np.testing.assert_allclose(marker_centres(corners), expected, atol=1e-9)
    degenerate = np.array([[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]]])
    assert np.isnan(marker_centres(degenerate)).all()


def ids_found(detectors: dict, view, markers: str, rng, trials: int = 12) -> dict[str, int]:
    """How often each detector finds the marker of ``trials`` views (``view(rng, id)``);
    a wrong id fails the test."""
    found = dict.fromkeys(detectors, 0)
    for trial in range(trials):
        marker_id = int(rng.integers(0, family_info(markers).id_count))
        image = view(rng, marker_id)
        for name, detector in detectors.items():
            ids, _ = detector.detect(image)
            assert set(ids.tolist()) <= {marker_id}, (name, trial, ids)
            found[name] += int(marker_id in ids.tolist())
    return found


def saturated_view(bits: np.ndarray, H: np.ndarray, size: int, gain: float) -> np.ndarray:
    """A projected (inverted) marker seen by a camera whose automatic exposure raised its
    gain for the dark floor: optical blur first, then the sensor clips, so the white
    modules bloom into the black ones."""
    import cv2

    irradiance = 1.0 - render_warped(bits, H, (size, size)) / 255.0  # white marker on black
    irradiance = 0.04 + 0.5 * irradiance
    blurred = cv2.GaussianBlur(irradiance, (0, 0), 1.0)
    return np.rint(255 * np.clip(gain * blurred, 0, 1) ** (1 / 2.2)).astype(np.uint8)


def test_saturated_markers_keep_their_bits():
    """Read from module centres at 8 px per module, bloomed markers keep their ids where
    OpenCV's defaults (4 px, 0.13 of the module ignored) read no code or a wrong one."""
    rng = np.random.default_rng(11)
    markers = "aruco:4X4_50"
    ours = MarkerDetector(markers, inverted=True)
    opencv = MarkerDetector(markers, inverted=True, perspective_remove_pixel_per_cell=4,
                            perspective_remove_ignored_margin_per_cell=0.13)
    def view(trial_rng, marker_id):
        return saturated_view(marker_bits(markers, marker_id), random_view(trial_rng, 6, 30.0, 72), 72, gain=3.0)

    found = ids_found({"ours": ours, "opencv": opencv}, view, markers, rng)
    assert found["ours"] >= 10
    assert found["ours"] >= found["opencv"] + 4


def test_markers_under_room_light_are_found():
    """Room light lifts the floor to the projector's white but for a few tens of grey
    levels: the adaptive threshold's constant follows the image's contrast, so small
    markers are still segmented where the fixed constant (7 levels) loses most."""
    rng = np.random.default_rng(5)
    markers = "aruco:4X4_50"
    ours = MarkerDetector(markers, inverted=True)
    fixed = MarkerDetector(markers, inverted=True, thresh_constant_contrast_share=0.0)
    def view(trial_rng, marker_id):
        marker = render_warped(marker_bits(markers, marker_id), random_view(trial_rng, 6, 16.0, 64), (64, 64)) / 255.0
        image = 200.0 - 40.0 * marker + trial_rng.normal(0.0, 1.5, marker.shape)  # floor 160, white 200
        return np.clip(np.rint(image), 0, 255).astype(np.uint8)

    found = ids_found({"ours": ours, "fixed": fixed}, view, markers, rng)
    assert found["ours"] >= 10
    assert found["ours"] >= found["fixed"] + 4
