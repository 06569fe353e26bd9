"""The HTML report: self-contained, every plot embedded and saved, every camera named,
a failed camera shown with its reason."""

from __future__ import annotations

import base64
import re

import numpy as np
import pytest

from calibproj.cli.main import main
from calibproj.formats.intrinsics import write_intrinsics_dir
from calibproj.registration.driver import register
from calibproj.report import write_report
from calibproj.simulate import simulate_tracks

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# Plots of the whole calibration: errors per camera, 3D scene, top and side views; with
# uncertainty.json (calibrate writes it) the maps of the expected 3D error.
SCENE_PLOTS = 3
ERROR_MAPS = 3  # floor, table and head heights
# Plots of each camera: error histogram, residuals over the image, coverage (and a
# frame of its video with its detections, when calibrated from videos).
CAMERA_PLOTS = 3


def starved(tracks, camera: str, keep: int):
    """The tracks with only ``keep`` observations left to one camera, so that it fails."""
    rows = np.flatnonzero(tracks.camera_index == tracks.camera_names.index(camera))
    mask = np.ones(len(tracks), dtype=bool)
    mask[rows[keep:]] = False
    return tracks.select(mask)


@pytest.fixture(scope="module")
def report_with_a_failed_camera(tmp_path_factory):
    sim = simulate_tracks("small", None, noise_px=0.3, seed=6)
    tracks = starved(sim.tracks, "cam3", 4)
    calibration = register(tracks, sim.intrinsics)
    assert list(calibration.failed) == ["cam3"]
    out = tmp_path_factory.mktemp("report")
    calibration.save(out)
    write_intrinsics_dir(out / "intrinsics", sim.intrinsics)
    tracks.write(out / "tracks.json")
    return write_report(out), calibration  # tracks and intrinsics from the results folder


def embedded_images(page: str) -> list[bytes]:
    return [base64.b64decode(data) for data in re.findall(r'<img [^>]*src="data:image/png;base64,([^"]+)"', page)]


def test_report_embeds_every_plot_and_saves_it(report_with_a_failed_camera) -> None:
    path, calibration = report_with_a_failed_camera
    page = path.read_text(encoding="utf-8")
    images = embedded_images(page)
    assert len(images) == page.count("<img ") == SCENE_PLOTS + CAMERA_PLOTS * len(calibration.metrics)
    assert all(image.startswith(PNG_SIGNATURE) for image in images)
    files = sorted((path.parent / "report").glob("*.png"))
    assert len(files) == len(images)
    assert sorted(f.read_bytes() for f in files) == sorted(images)


def test_report_is_self_contained(report_with_a_failed_camera) -> None:
    """Nothing is loaded from elsewhere: images embedded, the 3D view's library inline
    (its code names web addresses it never fetches for a 3D scatter: map tiles, fonts)."""
    page = report_with_a_failed_camera[0].read_text(encoding="utf-8")
    assert not re.search(r"<(script|img|iframe)[^>]*\ssrc=[\"']?(https?:)?//", page)
    assert "<link" not in page and "@import" not in page
    scripts = re.findall(r"<script[^>]*>", page)
    assert scripts and all("src=" not in tag for tag in scripts)  # the 3D view, inline
    assert 'class="interactive"' in page and "Plotly.newPlot" in page


def test_report_names_every_camera_and_the_failure(report_with_a_failed_camera) -> None:
    path, calibration = report_with_a_failed_camera
    page = path.read_text(encoding="utf-8")
    for name in ("cam1", "cam2", "cam3"):
        assert f"<h3>{name}</h3>" in page
    reason = calibration.failed["cam3"]
    failed_cells = re.findall(r'<td class="failed"[^>]*>([^<]*)</td>', page)
    assert failed_cells == [f"FAILED: {reason}"]
    assert page.count('class="failed"') == 3  # in the headline, the table and the camera's section


def test_calibrate_writes_the_report_by_default(tmp_path, capsys) -> None:
    simulate_tracks("small", tmp_path / "sim", noise_px=0.3, seed=6)
    status = main(["calibrate", "--tracks", str(tmp_path / "sim" / "tracks.json"), "--intrinsics",
                   str(tmp_path / "sim" / "intrinsics"), "--out", str(tmp_path / "r")])
    assert status == 0
    page = (tmp_path / "r" / "report.html").read_text(encoding="utf-8")
    assert len(embedded_images(page)) == SCENE_PLOTS + ERROR_MAPS + CAMERA_PLOTS * 3
    assert (tmp_path / "r" / "report" / "scene_3d.png").is_file()
    assert (tmp_path / "r" / "report" / "uncertainty_table.png").is_file()
    assert sorted(p.name for p in (tmp_path / "r" / "intrinsics").iterdir()) == ["cam1.json", "cam2.json", "cam3.json"]


def test_missing_results_folder_is_one_clear_error(tmp_path) -> None:
    with pytest.raises(FileNotFoundError, match="no such results folder"):
        write_report(tmp_path / "absent", tmp_path / "tracks.json")


def test_uncertainty_circles_are_magnified_to_a_visible_size() -> None:
    """The largest 3-sigma circle becomes 4 % of the scene; the factor is printed on the
    plot, so circles compare between cameras and read back to sigma."""
    from types import SimpleNamespace

    from calibproj.report.figures import UNCERTAINTY_SHARE, uncertainty_magnification

    def view(sigma):
        return SimpleNamespace(metrics=None if sigma is None else SimpleNamespace(centre_sigma=sigma))

    views = [view(0.001), view(0.004), view(None)]
    assert uncertainty_magnification(views, 10.0) == pytest.approx(UNCERTAINTY_SHARE * 10.0 / 0.012)
    assert uncertainty_magnification([view(None)], 10.0) == 1.0
    assert uncertainty_magnification([view(5.0)], 10.0) == 1.0  # already larger: never shrunk


def test_sync_table_gives_each_cameras_sync_with_its_uncertainty_and_failures() -> None:
    from calibproj.report.page import sync_table

    report = {"cameras": {
        "cam1": {"status": "ok", "sync": {"offset_s": 1.25, "offset_uncertainty_frames": 0.3, "camera_fps": 30.0,
                                          "drift_ppm": 12.34, "exposure_frames": 0.5, "readout_s": 0.015,
                                          "readout_sigma_s": 0.0004},
                 "frames": {"decoded": 700, "dropped": 14, "duplicated": 1},
                 "patterns": {"whole_frame": 3, "in_regions": 90, "dropped": 2, "missing": 1},
                 "scales": [{"scale": 1.0, "kept": 40}, {"scale": 3.0, "kept": 80}], "detections_inconsistent": 5},
        "cam2": {"status": "failed", "error": "cam2.mp4: start light code not found <here>"},
    }}
    page = sync_table(report)
    assert "1.2500 &plusmn; 0.0100" in page  # 0.3 frame at 30 fps
    assert "15.00 &plusmn; 0.40" in page and "12.3" in page
    assert "700 / 14 / 1" in page and "93 / 2 / 1" in page and "40 at 1x, 80 at 3x" in page
    assert "FAILED: cam2.mp4: start light code not found &lt;here&gt;" in page


def test_the_page_fits_a_phone() -> None:
    """A viewport, tables that scroll sideways inside the page, plots in a grid that
    wraps to one column and images that shrink to the screen."""
    from calibproj.report.page import STYLE, _scroll

    assert "max-width: 100%" in STYLE and "overflow-x: auto" in STYLE and "auto-fit" in STYLE
    # Printed, a wide table is not clipped by its scrolling box.
    printed = STYLE.split("@media print {")[1].split("\n}\n")[0]
    assert ".scroll { overflow: visible; }" in printed and "width: 100%" in printed
    assert _scroll("<table></table>") == '<div class="scroll"><table></table></div>'


def test_report_page_has_viewport_warnings_numbers_and_no_provenance_note(report_with_a_failed_camera) -> None:
    page = report_with_a_failed_camera[0].read_text(encoding="utf-8")
    assert '<meta name="viewport" content="width=device-width, initial-scale=1">' in page
    assert "Camera cam3 FAILED" in page  # in the headline above the tables
    assert "Positions and intrinsics" in page and "tilt from down [deg]" in page
    assert "No provenance recorded" in page  # results written without calibrate
    # Coplanar: the floor's line says whether the relief test found it uneven (a test at
    # 99.9 %, so on a flat simulated floor either verdict can come; both texts are checked
    # in test_the_summary_says_when_the_floors_relief_was_estimated).
    calibration = report_with_a_failed_camera[1]
    assert ("kept flat" if calibration.floor_rms < 1e-9 else "relief, estimated") in page
    # The first screen answers whether every camera is OK: a line per camera, the
    # reference named, the others with their sigmas, the failure with its reason.
    head = re.search(r'<div class="headline">(.*?)</div>', page).group(1)
    assert f"<b>{len(calibration.poses)} of 3 cameras calibrated</b>" in head and head.count("<li") == 3
    assert f"Camera cam3 FAILED: {calibration.failed['cam3']}" in head
    assert re.search(r"cam2(: ok,| is WEAK:) rotation \d\.\d{4} deg, centre \d+\.\d+ ", head)
    # The first registered camera is named the reference, not given sigmas of 0.
    reference = report_with_a_failed_camera[1].registration_order[0]
    row = re.search(rf'>{reference}</a></td>(.*?)</tr>', page).group(1)
    assert "reference (the others' sigmas are relative to it)" in row and "0.0000" not in row
    assert page.count("reference (the others' sigmas are relative to it)") == 2  # the headline and the table


def test_error_bar_whiskers_stop_at_zero() -> None:
    from calibproj.report.figures import error_whiskers

    lower, upper = error_whiskers([0.02, 0.5], [0.05, 0.1])
    np.testing.assert_allclose(lower, [0.02, 0.1])  # never below zero
    np.testing.assert_allclose(upper, [0.05, 0.1])


def test_a_camera_without_observations_is_drawn_empty(report_with_a_failed_camera) -> None:
    """Its coverage plot shows no observed cell (a colour scale of 0..0 used to paint every cell full)."""
    import cv2

    from calibproj.formats.intrinsics import load_intrinsics_dir
    from calibproj.report.data import camera_views
    from calibproj.report.figures import camera_coverage
    from calibproj.formats.tracks import Tracks

    path, calibration = report_with_a_failed_camera
    tracks = Tracks.read(path.parent / "tracks.json")
    intrinsics = load_intrinsics_dir(path.parent / "intrinsics")
    empty = [v for v in camera_views(calibration, tracks.select(tracks.camera_index != 0), intrinsics)
             if v.name == tracks.camera_names[0]][0]
    assert len(empty.observed_px) == 0
    image = cv2.imdecode(np.frombuffer(camera_coverage(empty), np.uint8), cv2.IMREAD_COLOR)
    b, g, r = (image[..., i].astype(int) for i in range(3))
    green = (g - np.maximum(r, b)) > 60
    assert green.mean() < 0.02  # only the colour bar


def test_numbers_table_gives_centre_height_tilt_and_heading() -> None:
    """A camera 2.5 m above (1, -2) looking straight down; another tilted 30 deg towards +x."""
    from types import SimpleNamespace

    from calibproj.formats.calibration import Calibration, CameraMetrics
    from calibproj.formats.intrinsics import Intrinsics
    from calibproj.report.page import numbers_table

    def pose(centre, tilt_deg):
        a = np.radians(tilt_deg)
        axis = np.array([np.sin(a), 0.0, -np.cos(a)])
        x = np.array([0.0, -1.0, 0.0])
        R = np.vstack([x, np.cross(axis, x), axis])
        return R, -R @ np.asarray(centre, dtype=float)

    poses = {"down": pose([1.0, -2.0, 2.5], 0.0), "tilted": pose([0.0, 0.0, 3.0], 30.0)}
    metrics = {n: CameraMetrics(0.1, 0.05, 10, 10, 10, 10, centre_sigma=0.0012) for n in poses}
    calibration = Calibration(poses, {}, metrics, np.zeros((0, 3)), np.zeros(0, dtype=np.int64), unit="m")
    camera = Intrinsics(name="any", K=np.array([[900.0, 0, 640], [0, 905.0, 360], [0, 0, 1]]),
                        dist=[-0.1, 0.02, 0, 0, 0], resolution=(1280, 720))
    views = [SimpleNamespace(name=n, registered=True, pose=poses[n], metrics=metrics[n], intrinsics=camera,
                             image_size=lambda: (1280.0, 720.0)) for n in poses]
    rows = numbers_table(calibration, views).split("</tr>")
    cells = [re.findall(r"<td[^>]*>([^<]*)</td>", row) for row in rows[1:3]]
    assert cells[0][:7] == ["down", "1.0000", "-2.0000", "2.5000", "1.20", "0.00", "0.0"]
    assert cells[1][3] == "3.0000" and cells[1][5] == "30.00" and cells[1][6] == "0.0"
    # One precision per column (k1 as the self-calibration table gives it), never "-0.0".
    assert cells[1][7:13] == ["900.0", "905.0", "640.0", "360.0", "-0.1000", "0.0200"]
    assert not any(re.fullmatch(r"-0\.0*", cell) for row in cells for cell in row)


def test_numbers_are_never_minus_zero() -> None:
    from calibproj.report.page import _number

    assert [_number(v, 3) for v in (-0.0, -1e-9, -0.0004, -0.0006, 2.5, None, True)] == [
        "0.000", "0.000", "0.000", "-0.001", "2.500", "-", "-"]


def test_a_bad_intrinsics_file_leaves_its_camera_without_intrinsics(report_with_a_failed_camera, tmp_path,
                                                                     caplog) -> None:
    """The report of a folder whose cam1 file went bad is still written: cam1 without
    intrinsics (no coverage frame), the log naming the file."""
    import shutil

    path, _ = report_with_a_failed_camera
    folder = tmp_path / "results"
    shutil.copytree(path.parent, folder)
    (folder / "intrinsics" / "cam1.json").write_text('{"schema": "calibproj.intrinsics/1", "K": true}')
    page = write_report(folder).read_text(encoding="utf-8")
    assert "<h3>cam1</h3>" in page and "<h3>cam2</h3>" in page
    assert any(str(folder / "intrinsics" / "cam1.json") in r.getMessage() for r in caplog.records)


def test_the_summary_says_when_the_floors_relief_was_estimated(report_with_a_failed_camera) -> None:
    from calibproj.report.page import _summary

    calibration = report_with_a_failed_camera[1]
    uneven = calibration.replace(floor_rms=0.0003)  # what a relief the test found leaves
    assert "relief, estimated" in _summary(uneven, [], None)
    assert "kept flat" in _summary(calibration.replace(floor_rms=0.0), [], None)
