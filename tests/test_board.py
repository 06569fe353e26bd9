"""calibproj intrinsics: a camera's intrinsics from views of a chessboard or a ChArUco
board, rendered here through a known camera (pinhole with distortion)."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibproj.board import BoardDetector, BoardOptions, BoardSpec, calibrate_with_board
from calibproj.cli.main import main
from calibproj.formats.intrinsics import read_intrinsics

SIZE = (640, 480)
K_TRUE = np.array([[520.0, 0.0, 322.0], [0.0, 518.0, 236.0], [0.0, 0.0, 1.0]])
DIST_TRUE = np.array([-0.21, 0.06, 0.0008, -0.0005, 0.0])
CHESSBOARD = BoardSpec.parse("chessboard:9x6:0.03")
TEXTURE_PX_PER_M = 4000.0


def chessboard_texture(spec: BoardSpec) -> tuple[np.ndarray, np.ndarray]:
    """The board drawn with a white margin; and the texture pixel of board point (0, 0)."""
    square = int(spec.square_m * TEXTURE_PX_PER_M)
    squares_x, squares_y = spec.columns + 1, spec.rows + 1
    margin = square
    texture = np.full((squares_y * square + 2 * margin, squares_x * square + 2 * margin), 255, np.uint8)
    for a in range(squares_x):
        for b in range(squares_y):
            if (a + b) % 2 == 0:
                rows = slice(margin + b * square, margin + (b + 1) * square)
                texture[rows, margin + a * square:margin + (a + 1) * square] = 0
    return texture, np.array([margin + square, margin + square], dtype=float)


def charuco_texture(spec: BoardSpec) -> tuple[np.ndarray, np.ndarray]:
    board = cv2.aruco.CharucoBoard((spec.columns, spec.rows), spec.square_m, spec.marker_m,
                                   cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    size = (int(spec.columns * spec.square_m * TEXTURE_PX_PER_M), int(spec.rows * spec.square_m * TEXTURE_PX_PER_M))
    margin = int(spec.square_m * TEXTURE_PX_PER_M)
    image = board.generateImage(size, marginSize=0)
    padded = cv2.copyMakeBorder(image, margin, margin, margin, margin, cv2.BORDER_CONSTANT, value=255)
    # ChArUco board coordinates start at the board's outer corner.
    return padded, np.array([margin, margin], dtype=float)


def render(texture: np.ndarray, origin_px: np.ndarray, rvec, tvec, blur: float = 0.6) -> np.ndarray:
    """The board seen by the true camera: each distorted pixel's ray hits the board plane."""
    u, v = np.meshgrid(np.arange(SIZE[0], dtype=np.float32), np.arange(SIZE[1], dtype=np.float32))
    pixels = np.stack([u.ravel(), v.ravel()], axis=1).reshape(-1, 1, 2)
    normalised = cv2.undistortPointsIter(pixels, K_TRUE, DIST_TRUE, None, None,
                                         (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10)).reshape(-1, 2)
    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=float))
    H = np.column_stack([R[:, 0], R[:, 1], np.asarray(tvec, dtype=float)])  # board (X, Y, 1) -> normalised
    board = np.linalg.solve(H, np.column_stack([normalised, np.ones(len(normalised))]).T).T
    xy = board[:, :2] / board[:, 2:]
    map_x = (xy[:, 0] * TEXTURE_PX_PER_M + origin_px[0]).reshape(SIZE[1], SIZE[0]).astype(np.float32)
    map_y = (xy[:, 1] * TEXTURE_PX_PER_M + origin_px[1]).reshape(SIZE[1], SIZE[0]).astype(np.float32)
    # Area sampling: the texture is much finer than a camera pixel.
    small = cv2.resize(texture, None, fx=0.25, fy=0.25, interpolation=cv2.INTER_AREA)
    image = cv2.remap(small, map_x / 4.0, map_y / 4.0, cv2.INTER_LINEAR, borderValue=128)
    image = cv2.GaussianBlur(image, (0, 0), blur) if blur > 0 else image
    noise = np.random.default_rng(int(1e3 * abs(float(np.sum(tvec))))).normal(0, 1.5, image.shape)
    return np.clip(image.astype(float) * 0.8 + 25 + noise, 0, 255).astype(np.uint8)


def poses(count: int, centre: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Tilted views of the board spread over the image (the board's centre at ``centre``)."""
    rng = np.random.default_rng(4)
    out = []
    for k in range(count):
        rvec = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3)])
        R, _ = cv2.Rodrigues(rvec)
        shift = np.array([0.09 * np.cos(2 * np.pi * k / count), 0.07 * np.sin(2 * np.pi * k / count), 0.0])
        tvec = np.array([0.0, 0.0, rng.uniform(0.42, 0.55)]) + shift - R @ centre
        out.append((rvec, tvec))
    return out


@pytest.fixture(scope="module")
def chessboard_images(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("chessboard")
    texture, origin = chessboard_texture(CHESSBOARD)
    centre = np.array([4 * CHESSBOARD.square_m, 2.5 * CHESSBOARD.square_m, 0.0])
    for index, (rvec, tvec) in enumerate(poses(14, centre)):
        cv2.imwrite(str(folder / f"left{index + 1:02d}.png"), render(texture, origin, rvec, tvec))
    return folder


def test_a_chessboard_gives_the_true_intrinsics(chessboard_images: Path) -> None:
    result = calibrate_with_board(chessboard_images, CHESSBOARD)
    K = result.intrinsics.K
    assert result.found == result.seen == 14 and len(result.views) == 14
    assert abs(K[0, 0] / K_TRUE[0, 0] - 1) < 0.005 and abs(K[1, 1] / K_TRUE[1, 1] - 1) < 0.005
    assert np.hypot(K[0, 2] - K_TRUE[0, 2], K[1, 2] - K_TRUE[1, 2]) < 2.0
    assert abs(result.intrinsics.dist[0] - DIST_TRUE[0]) < 0.01
    # The whole model (matrix and distortion) over the part of the image the views
    # covered: where a pixel's ray goes, within half a pixel of the truth.
    seen = np.vstack([v.image_points for v in result.views])
    low, high = np.percentile(seen, 10, axis=0), np.percentile(seen, 90, axis=0)
    grid = np.stack(np.meshgrid(np.linspace(low[0], high[0], 5), np.linspace(low[1], high[1], 5)), -1)
    grid = grid.reshape(-1, 1, 2)
    true = cv2.undistortPoints(grid, K_TRUE, DIST_TRUE, P=K_TRUE)
    estimated = cv2.undistortPoints(grid, K, result.intrinsics.dist, P=K_TRUE)
    assert np.abs(true - estimated).max() < 0.5
    assert result.rms_px < 0.2 and result.view_rms_px.shape == (14,)
    # Each parameter's sigma is small and the truth within a few of them.
    assert 0 < result.sigmas["fx"] < 3.0 and abs(K[0, 0] - K_TRUE[0, 0]) < 5 * result.sigmas["fx"] + 0.5


def test_the_same_as_opencv_on_the_same_images(chessboard_images: Path) -> None:
    """With OpenCV's own corner finder and every view kept, the result is
    cv2.calibrateCamera's on those images, as in OpenCV's calibration sample."""
    object_points, image_points = [], []
    grid = np.zeros((9 * 6, 3), np.float32)
    grid[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * 0.03
    for path in sorted(chessboard_images.iterdir()):
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        found, corners = cv2.findChessboardCorners(gray, (9, 6), None)
        assert found, path
        corners = cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1),
                                   (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001))
        object_points.append(grid)
        image_points.append(corners)
    rms, K, dist, _, _ = cv2.calibrateCamera(object_points, image_points, SIZE, None, None)
    ours = calibrate_with_board(chessboard_images, CHESSBOARD,
                                options=BoardOptions(classic_detector=True, min_sharpness_share=0.0))
    # Equal but for the last digits (calibrateCameraExtended vs calibrateCamera).
    np.testing.assert_allclose(ours.intrinsics.K, K, rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(ours.intrinsics.dist, dist.ravel(), rtol=1e-6, atol=1e-9)
    assert ours.rms_px == pytest.approx(rms, rel=1e-8)


def test_a_blurred_view_is_left_out(chessboard_images: Path, tmp_path: Path) -> None:
    folder = tmp_path / "images"
    folder.mkdir()
    for path in sorted(chessboard_images.iterdir()):
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if path.name == "left03.png":
            image = cv2.GaussianBlur(image, (0, 0), 2.5)
        cv2.imwrite(str(folder / path.name), image)
    result = calibrate_with_board(folder, CHESSBOARD)
    labels = [v.label for v in result.views]
    assert "left03.png" not in labels and len(labels) == 13
    assert list(result.left_out) == ["left03.png"] and result.left_out["left03.png"].startswith("blurred (sharpness")


def test_views_are_chosen_for_coverage(chessboard_images: Path) -> None:
    result = calibrate_with_board(chessboard_images, CHESSBOARD, options=BoardOptions(max_views=5))
    assert len(result.views) == 5
    cells = {tuple(c) for v in result.views for c in np.floor(v.image_points / 80).astype(int)}
    first_five = calibrate_with_board(chessboard_images, CHESSBOARD, options=BoardOptions(max_views=14)).views[:5]
    cells_first = {tuple(c) for v in first_five for c in np.floor(v.image_points / 80).astype(int)}
    assert len(cells) >= len(cells_first)


def test_a_charuco_board_partly_hidden(tmp_path: Path) -> None:
    spec = BoardSpec.parse("charuco:7x5:0.03:0.022:4X4_50")
    texture, origin = charuco_texture(spec)
    centre = np.array([3.5 * spec.square_m, 2.5 * spec.square_m, 0.0])
    for index, (rvec, tvec) in enumerate(poses(12, centre)):
        image = render(texture, origin, rvec, tvec)
        if index == 0:  # the right third of the board hidden: the corners seen still count
            _, corners = BoardDetector(spec).detect(image)
            image[:, int(np.percentile(corners[:, 0], 66)):] = 128
        cv2.imwrite(str(tmp_path / f"view{index:02d}.png"), image)
    result = calibrate_with_board(tmp_path, spec)
    assert result.found == 12
    assert abs(result.intrinsics.K[0, 0] / K_TRUE[0, 0] - 1) < 0.01
    assert len(result.views[0].image_points) < spec.corner_count()


def test_the_command_writes_intrinsics_and_a_plot(chessboard_images: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "far1.json"
    assert main(["intrinsics", str(chessboard_images), "--board", "chessboard:9x6:0.03", "--out", str(out),
                 "--plot", str(tmp_path / "coverage.png"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    written = read_intrinsics(out)
    assert written.name == "far1" and tuple(written.resolution) == SIZE
    np.testing.assert_allclose(written.K, summary["K"])
    assert (tmp_path / "coverage.png").read_bytes().startswith(b"\x89PNG")
    assert summary["images"] == {"seen": 14, "board_found": 14, "used": 14} and len(summary["views"]) == 14
    # The file carries what README promises: how they were measured, beside them.
    measured = json.loads(out.read_text())["board_calibration"]
    assert set(measured["sigmas"]) >= {"fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"}
    assert all(0 < measured["sigmas"][name] < 2.0 for name in ("fx", "fy", "cx", "cy"))
    assert [view["label"] for view in measured["views"]] == [view["label"] for view in summary["views"]]
    assert all(0 < view["rms_px"] < 1.0 for view in measured["views"]) and measured["left_out"] == []
    # Without --force an existing file stays.
    assert main(["intrinsics", str(chessboard_images), "--board", "chessboard:9x6:0.03", "--out", str(out)]) == 2
    assert "exists" in capsys.readouterr().err


def test_views_left_out_are_named_with_why(chessboard_images: Path, tmp_path: Path, capsys) -> None:
    folder = tmp_path / "images"
    folder.mkdir()
    for path in sorted(chessboard_images.iterdir())[:8]:
        shutil.copy(path, folder / path.name)
    cv2.imwrite(str(folder / "wall.png"), np.full(SIZE[::-1], 128, np.uint8))
    out = tmp_path / "near1.json"
    assert main(["intrinsics", str(folder), "--board", "chessboard:9x6:0.03", "--out", str(out),
                 "--max-views", "5"]) == 0
    printed = capsys.readouterr().out
    assert "left out, board not found: wall.png" in printed
    assert re.search(r"left out, not needed: left\d\d.png, left\d\d.png, left\d\d.png\n", printed)
    left_out = {entry["label"]: entry["reason"] for entry in json.loads(out.read_text())["board_calibration"]["left_out"]}
    assert left_out["wall.png"] == "board not found" and len(left_out) == 4


def test_a_chessboard_given_by_its_squares_is_explained(chessboard_images: Path, tmp_path: Path, capsys) -> None:
    """chessboard:10x7 for a board of 10x7 squares (9x6 inner corners): found nowhere,
    and the message says what COLSxROWS counts and what is found."""
    assert main(["intrinsics", str(chessboard_images), "--board", "chessboard:10x7:0.03",
                 "--out", str(tmp_path / "far1.json")]) == 2
    line = capsys.readouterr().err.strip()
    assert "the board chessboard:10x7:0.03 was found in 0 of 14 images" in line
    assert line.endswith("(chessboard COLSxROWS counts inner corners, squares minus one: chessboard:9x6:0.03 is "
                         "found in 6 of the first 6 images)")


@pytest.mark.parametrize("board, message", [
    ("chessboard:9x6", "expected chessboard:COLSxROWS"),
    ("chessboard:9by6:0.03", "two integers"),
    ("chessboard:1x6:0.03", "columns and rows"),
    ("charuco:5x7:0.04:0.05:4X4_50", "marker must be smaller"),
    ("charuco:5x7:0.04:0.03:9X9_1", "unknown ArUco dictionary"),
    # Found by fuzzing: OpenCV raised on these (more than 2 inner corners each way; a
    # marker of a denormal size).
    ("chessboard:2x2:0.03", "columns and rows must be in [3, 200]"),
    ("charuco:5x7:0.04:1e-320:4X4_50", "at least 5% of it"),
    ("chessboard:9x6:1e-320", "the square size must be 0.0001 to 10 m"),
    ("chessboard:9x6:30", "the square size must be 0.0001 to 10 m"),
])
def test_bad_boards_are_one_line(board: str, message: str, tmp_path: Path, capsys) -> None:
    assert main(["intrinsics", str(tmp_path), "--board", board, "--out", str(tmp_path / "c.json")]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and message in error[0]


def test_outputs_are_checked_before_the_calibration(tmp_path: Path, capsys) -> None:
    """Found by probing: --out and --plot on one path wrote the picture over the
    intrinsics and exited 0; an --out that cannot be written was found after the whole
    calibration, named by its hidden temporary file. Both are one line naming the path,
    before any image is read (the image folder here does not even exist)."""
    images = tmp_path / "no-images"
    out = tmp_path / "c.json"
    assert main(["intrinsics", str(images), "--board", "chessboard:9x6:0.03", "--out", str(out),
                 "--plot", str(out)]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "--plot and --out are the same file" in error[0] and not out.exists()
    (tmp_path / "a-file").write_text("")
    blocked = tmp_path / "a-file" / "c.json"
    assert main(["intrinsics", str(images), "--board", "chessboard:9x6:0.03", "--out", str(blocked)]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and error[0].endswith(f"{blocked}: {blocked.parent} is not a folder")


def test_a_bad_image_costs_that_image_only(chessboard_images: Path, tmp_path: Path, capsys) -> None:
    """Found by probing: one PNG whose header claims 100000 x 100000 px aborted the run
    (OpenCV refuses to decode it), and the 14 good images went unused."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    folder = tmp_path / "images"
    folder.mkdir()
    for path in sorted(chessboard_images.iterdir()):
        (folder / path.name).write_bytes(path.read_bytes())
    (folder / "huge.png").write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 100000, 100000, 8, 0, 0, 0, 0))
                                      + chunk(b"IDAT", zlib.compress(b"\0" * 100)) + chunk(b"IEND", b""))
    out = tmp_path / "far1.json"
    assert main(["intrinsics", str(folder), "--board", "chessboard:9x6:0.03", "--out", str(out), "--json"]) == 0
    captured = capsys.readouterr()
    assert f"{folder / 'huge.png'}: not an image OpenCV can read; skipped" in captured.err
    assert json.loads(captured.out)["images"]["used"] == 14 and out.exists()


def test_too_few_views_name_the_source(chessboard_images: Path, tmp_path: Path, capsys) -> None:
    folder = tmp_path / "two"
    folder.mkdir()
    for path in sorted(chessboard_images.iterdir())[:2]:
        (folder / path.name).write_bytes(path.read_bytes())
    (folder / "broken.png").write_bytes(b"not a png")
    assert main(["intrinsics", str(folder), "--board", "chessboard:9x6:0.03", "--out", str(tmp_path / "c.json")]) == 2
    error = capsys.readouterr().err
    assert "broken.png" in error
    (folder / "broken.png").unlink()
    assert main(["intrinsics", str(folder), "--board", "chessboard:9x6:0.03", "--out", str(tmp_path / "c.json")]) == 2
    assert f"{folder}: the board chessboard:9x6:0.03 was found in 2 of 2 images" in capsys.readouterr().err


OPENCV_SAMPLES = Path("/usr/share/doc/opencv-doc/examples/data")  # Debian's opencv-doc (tools/install_deps.sh)


def test_opencv_sample_chessboards_give_what_opencv_gives(tmp_path: Path, capsys) -> None:
    """OpenCV's own sample views (left01..14.jpg of its calibration sample, 9x6 inner
    corners): ``calibproj intrinsics`` with OpenCV's corner finder and every view equals
    cv2.calibrateCamera on them."""
    images = tmp_path / "left"
    images.mkdir()
    samples = sorted(OPENCV_SAMPLES.glob("left[0-9][0-9].jpg"))
    assert len(samples) == 13, f"{OPENCV_SAMPLES}: OpenCV's sample images missing (Debian package opencv-doc)"
    for path in samples:
        (images / path.name).write_bytes(path.read_bytes())
    object_points, image_points, size = [], [], None
    grid = np.zeros((9 * 6, 3), np.float32)
    grid[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * 0.025
    for path in samples:
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        size = gray.shape[::-1]
        found, corners = cv2.findChessboardCorners(gray, (9, 6), None)
        if not found:
            continue
        corners = cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1),
                                   (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001))
        object_points.append(grid)
        image_points.append(corners)
    rms, K, dist, _, _ = cv2.calibrateCamera(object_points, image_points, size, None, None)
    out = tmp_path / "left.json"
    assert main(["intrinsics", str(images), "--board", "chessboard:9x6:0.025", "--out", str(out),
                 "--classic-detector", "--min-sharpness-share", "0", "--json"]) == 0
    document = json.loads(capsys.readouterr().out)
    ours = read_intrinsics(out)
    assert len(object_points) >= 12 and len(document["views"]) == len(object_points)
    np.testing.assert_allclose(ours.K, K, rtol=1e-7)
    np.testing.assert_allclose(ours.dist, dist.ravel(), rtol=1e-5, atol=1e-8)
    assert document["rms_px"] == pytest.approx(rms, rel=1e-7)


def mutated_images(data: bytes, rng: np.random.Generator, count: int) -> list[tuple[str, bytes]]:
    """A PNG truncated, with flipped bytes, emptied, replaced by text or by random bytes."""
    out = [("empty", b""), ("text", b"not an image\n"), ("random", rng.bytes(4096)),
           ("header only", data[:64]), ("half", data[: len(data) // 2])]
    while len(out) < count:
        flipped = bytearray(data)
        for position in rng.integers(0, len(data), int(rng.integers(1, 40))):
            flipped[position] = int(rng.integers(0, 256))
        out.append((f"{len(out)}: bytes flipped", bytes(flipped)))
    return out


def mutated_boards(rng: np.random.Generator, count: int) -> list[str]:
    """Board specs with wrong kinds, sizes, numbers and dictionaries."""
    values = ["0", "-1", "1e-320", "1e308", "nan", "inf", "x", "", "9x", "x6", "2x2", "201x3", "9x6x2", "0.03e"]
    out = ["", "chessboard", "charuco", "circles:9x6:0.03", "chessboard:9x6", "charuco:5x7:0.04:0.03",
           "charuco:5x7:0.04:0.03:NOPE_50", "chessboard:9x6:0.03:extra", ":::", "chessboard:9×6:0.03"]
    while len(out) < count:
        kind = rng.choice(["chessboard", "charuco"])
        # The size is always one of the bad values; square and marker may be good ones.
        size, square, marker = (str(rng.choice(values)), str(rng.choice(values + ["0.03"])),
                                str(rng.choice(values + ["0.02"])))
        out.append(f"{kind}:{size}:{square}" + (f":{marker}:4X4_50" if kind == "charuco" else ""))
    return out


def test_mutated_intrinsics_inputs_fail_cleanly(chessboard_images: Path, tmp_path: Path, capsys) -> None:
    """Fuzzing of `calibproj intrinsics`: one of the board images mutated (the run goes
    on with the others, the image named), or the board spec mutated (one error line).
    No traceback, no internal error, the documented exit statuses."""
    rng = np.random.default_rng(20251126)
    good = sorted(chessboard_images.iterdir())
    problems = []
    for index, (label, data) in enumerate(mutated_images(good[0].read_bytes(), rng, 16)):
        folder = tmp_path / f"images{index}"
        folder.mkdir()
        for path in good[:9]:
            (folder / path.name).write_bytes(path.read_bytes())
        (folder / good[0].name).write_bytes(data)
        status = main(["intrinsics", str(folder), "--board", "chessboard:9x6:0.03", "--out",
                       str(tmp_path / f"c{index}.json")])
        err = capsys.readouterr().err
        if status not in (0, 1) or "Traceback" in err or "internal error" in err:
            problems.append(f"image {label}: status {status}: {err[-300:]!r}")
    for index, board in enumerate(mutated_boards(rng, 40)):
        status = main(["intrinsics", str(chessboard_images), "--board", board, "--out",
                       str(tmp_path / f"b{index}.json")])
        err = capsys.readouterr().err.strip().splitlines()
        if status != 2 or len(err) != 1 or "Traceback" in err[0] or "internal error" in err[0]:
            problems.append(f"board {board!r}: status {status}: {err[-3:]!r}")
    assert not problems, "\n".join(problems)
