"""Assemble the report: plots to PNG files and one self-contained HTML page."""

from __future__ import annotations

import base64
import html
import json
import logging
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from calibproj.calibration import Calibration
from calibproj.io.intrinsics import Intrinsics
from calibproj.io.jsonio import atomic_write_bytes, atomic_write_text
from calibproj.report import figures
from calibproj.report.data import CameraView, camera_views
from calibproj.results import DETECT_REPORT_FILE, TRACKS_FILE, load_results, resolve_intrinsics
from calibproj.tracks import Tracks
from calibproj.version import __version__

logger = logging.getLogger(__name__)

REPORT_FILE = "report.html"
FIGURES_DIR = "report"

STYLE = """
body { font-family: sans-serif; margin: 2em auto; max-width: 1200px; color: #222; }
h1 { margin-bottom: 0.2em; }
table { border-collapse: collapse; margin: 1em 0; }
th, td { border: 1px solid #ccc; padding: 0.3em 0.7em; text-align: right; }
th { background: #f0f0f0; }
td.name, th.name { text-align: left; }
td.failed { color: #c0392b; text-align: left; font-weight: bold; }
.summary td { text-align: left; }
img { max-width: 100%; display: block; margin: 0.5em 0; }
p.failed { color: #c0392b; font-weight: bold; }
section.camera { border-top: 1px solid #ddd; margin-top: 1.5em; }
"""


@dataclass(frozen=True)
class Plot:
    """One plot: its file name, caption and PNG bytes."""

    file_name: str
    caption: str
    png: bytes


def write_report(
    results_dir: str | os.PathLike,
    tracks: Tracks | str | os.PathLike | None = None,
    intrinsics: Mapping[str, Intrinsics] | str | os.PathLike | None = None,
    dpi: int = figures.DEFAULT_DPI,
) -> Path:
    """Write ``report.html`` and ``report/*.png`` into a results folder; returns the page's path.

    Args:
        results_dir: a folder written by ``calibproj calibrate`` (``camera_poses.json``, ...).
        tracks: the tracks the calibration was made from, ``Tracks`` or ``tracks.json``;
            ``None`` reads ``<results_dir>/tracks.json``.
        intrinsics: per-camera intrinsics or their folder; ``None`` reads
            ``<results_dir>/intrinsics``.
        dpi: resolution of the plots.
    """
    results_dir = Path(results_dir)
    calibration = load_results(results_dir)
    intrinsics = resolve_intrinsics(results_dir, intrinsics)
    if tracks is None:
        tracks = results_dir / TRACKS_FILE
    tracks = tracks if isinstance(tracks, Tracks) else Tracks.read(tracks)
    views = camera_views(calibration, tracks, intrinsics)
    scene, cameras = draw_plots(calibration, views, dpi)
    folder = results_dir / FIGURES_DIR
    for plot in [*scene, *cameras.values()]:
        atomic_write_bytes(folder / plot.file_name, plot.png)
    path = results_dir / REPORT_FILE
    atomic_write_text(path, render_page(calibration, views, scene, cameras, _detect_report(results_dir)))
    logger.info("report written: %s (%.1f MB)", path, path.stat().st_size / 1e6)
    return path


def draw_plots(calibration: Calibration, views: list[CameraView], dpi: int) -> tuple[list[Plot], dict[str, Plot]]:
    """The scene plots and one plot per camera (by name)."""
    scene = [Plot("errors.png", "Reprojection error per camera", figures.error_bars(views, dpi))]
    if calibration.poses:
        scene.append(Plot("scene_3d.png", "Cameras, floor and points", figures.scene_3d(calibration, views, dpi)))
        scene.append(Plot("scene_views.png", "Top and side views", figures.scene_views(calibration, views, dpi)))
    file_names = unique_file_names([v.name for v in views])
    cameras = {
        view.name: Plot(file_names[view.name], f"Camera {view.name}", figures.camera_panels(view, dpi))
        for view in views
    }
    return scene, cameras


def unique_file_names(names: list[str]) -> dict[str, str]:
    """``camera_<name>.png`` with characters unsafe in file names replaced, made unique."""
    out: dict[str, str] = {}
    taken: set[str] = set()
    for name in names:
        stem = "camera_" + re.sub(r"[^A-Za-z0-9_.-]", "_", name)
        candidate, suffix = stem, 1
        while candidate.lower() in taken:
            suffix += 1
            candidate = f"{stem}_{suffix}"
        taken.add(candidate.lower())
        out[name] = candidate + ".png"
    return out


# -- HTML -----------------------------------------------------------------------------------


def _detect_report(results_dir: Path) -> dict | None:
    """The results' detect_report.json (calibrated from videos), or None (from tracks,
    or unreadable: the report then has no sync section, and says why in the log)."""
    path = results_dir / DETECT_REPORT_FILE
    if not path.exists():
        return None
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as error:
        logger.warning("%s: not read (%s); the report has no sync and detection section", path, error)
        return None


def render_page(calibration: Calibration, views: list[CameraView], scene: list[Plot],
                cameras: dict[str, Plot], detect_report: dict | None = None) -> str:
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        "<title>calibproj calibration report</title>",
        f"<style>{STYLE}</style></head><body>",
        "<h1>Calibration report</h1>",
        _summary(calibration, views),
        "<h2>Cameras</h2>",
        _camera_table(views, cameras),
        *(["<h2>Sync and detection</h2>", sync_table(detect_report)] if detect_report else []),
        "<h2>Scene</h2>",
        *(_figure(plot) for plot in scene),
        "<h2>Per camera</h2>",
        *(_camera_section(view, cameras[view.name]) for view in views),
        f"<p><small>calibproj {html.escape(__version__)}</small></p>",
        "</body></html>",
    ]
    return "\n".join(parts) + "\n"


def _summary(calibration: Calibration, views: list[CameraView]) -> str:
    registered = sum(1 for v in views if v.registered)
    unit = "metres" if calibration.unit == "m" else "arbitrary (first camera at height 1)"
    rows = [
        ("registered cameras", f"{registered} of {len(views)}"),
        ("model", calibration.model),
        ("unit", unit),
        ("points", str(len(calibration.points))),
        ("floor RMS", f"{calibration.floor_rms:.4g}" + (" m" if calibration.unit == "m" else "")),
        ("registration order", ", ".join(calibration.registration_order) or "-"),
    ]
    body = "".join(f"<tr><th class=\"name\">{html.escape(k)}</th><td>{html.escape(v)}</td></tr>" for k, v in rows)
    return f'<table class="summary">{body}</table>'


def _camera_table(views: list[CameraView], cameras: dict[str, Plot]) -> str:
    header = ("<tr><th class=\"name\">camera</th><th>fit residual mean [px]</th><th>std [px]</th>"
              "<th>observations</th><th>inliers</th><th>track &ge; 2 observations</th><th>view score</th>"
              "<th>rotation &sigma; [deg]</th><th>centre &sigma;</th></tr>")
    rows = [header]
    for view in views:
        name = f'<td class="name"><a href="#{_anchor(cameras[view.name])}">{html.escape(view.name)}</a></td>'
        if not view.registered:
            reason = html.escape(view.failure or "not registered")
            rows.append(f'<tr>{name}<td class="failed" colspan="8">FAILED: {reason}</td></tr>')
            continue
        m = view.metrics
        cells = [_number(m.mean_px, 3), _number(m.std_px, 3), str(m.observations), str(m.inliers),
                 str(m.track2_observations), str(m.view_score), _number(m.rotation_sigma_deg, 4),
                 _number(m.centre_sigma, 4)] if m else ["-"] * 8
        weak = (f'<tr><td></td><td class="failed" colspan="8">WEAK: rotation known to '
                f'{m.rotation_sigma_deg:.3f} deg (1 sigma); more points in its view help</td></tr>'
                if m is not None and m.weak and m.rotation_sigma_deg is not None else "")
        rows.append(f"<tr>{name}" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>" + weak)
    return "<table>" + "".join(rows) + "</table>"


def sync_table(detect_report: dict) -> str:
    """Per camera: its sync to the projector with uncertainties, its frames and what
    the markers of each scale gave (``detect_report.json``'s values)."""
    header = ("<tr><th class=\"name\">camera</th><th>offset [s] &plusmn; 1&sigma;</th><th>drift [ppm]</th>"
              "<th>exposure [frames]</th><th>readout [ms] &plusmn; 1&sigma;</th>"
              "<th>frames decoded / dropped / duplicated</th><th>patterns used / dropped / missing</th>"
              "<th>markers kept per scale</th><th>detections off the floor homography</th></tr>")
    rows = [header]
    for name, camera in detect_report.get("cameras", {}).items():
        cell = f'<td class="name">{html.escape(str(name))}</td>'
        if camera.get("status") != "ok":
            reason = html.escape(str(camera.get("error", camera.get("status", "failed"))))
            rows.append(f'<tr>{cell}<td class="failed" colspan="8">FAILED: {reason}</td></tr>')
            continue
        rows.append(f"<tr>{cell}" + "".join(f"<td>{c}</td>" for c in _sync_cells(camera)) + "</tr>")
    return "<table>" + "".join(rows) + "</table>"


def _sync_cells(camera: dict) -> list[str]:
    sync, frames, patterns = camera.get("sync", {}), camera.get("frames", {}), camera.get("patterns", {})
    fps = sync.get("camera_fps") or 0.0
    offset_sigma = sync.get("offset_uncertainty_frames")
    offset = _number(sync.get("offset_s"), 4)
    if offset_sigma is not None and fps > 0:
        offset += f" &plusmn; {offset_sigma / fps:.4f}"
    readout = "-"
    if sync.get("readout_s") is not None:
        readout = f"{1e3 * sync['readout_s']:.2f} &plusmn; {1e3 * (sync.get('readout_sigma_s') or 0.0):.2f}"
    used = patterns.get("whole_frame", 0) + patterns.get("in_regions", 0)
    kept = ", ".join(f"{scale.get('kept', 0)} at {scale.get('scale', '?'):g}x" for scale in camera.get("scales", []))
    return [offset, _number(sync.get("drift_ppm"), 1), _number(sync.get("exposure_frames"), 2), readout,
            f"{frames.get('decoded', '-')} / {frames.get('dropped', '-')} / {frames.get('duplicated', '-')}",
            f"{used} / {patterns.get('dropped', '-')} / {patterns.get('missing', '-')}", kept,
            str(camera.get("detections_inconsistent", "-"))]


def _camera_section(view: CameraView, plot: Plot) -> str:
    title = f'<section class="camera" id="{_anchor(plot)}"><h3>{html.escape(view.name)}</h3>'
    status = "" if view.registered else f'<p class="failed">FAILED: {html.escape(view.failure or "")}</p>'
    return title + status + _figure(plot, with_caption=False) + "</section>"


def _figure(plot: Plot, with_caption: bool = True) -> str:
    data = base64.b64encode(plot.png).decode("ascii")
    caption = html.escape(plot.caption)
    below = f"<figcaption>{caption}</figcaption>" if with_caption else ""
    return f'<figure><img alt="{caption}" src="data:image/png;base64,{data}">{below}</figure>'


def _anchor(plot: Plot) -> str:
    """The camera plot's file stem: unique, and safe in a URL fragment."""
    return Path(plot.file_name).stem


def _number(value: float | None, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"
