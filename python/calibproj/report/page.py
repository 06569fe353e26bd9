"""Assemble the report: plots to PNG files and one self-contained HTML page."""

from __future__ import annotations

import base64
import hashlib
import html
import json
import logging
import math
import os
import re
import shlex
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibproj.formats.calibration import Calibration, Plane
from calibproj.formats.file_names import safe_file_names
from calibproj.formats.intrinsics import Intrinsics, intrinsics_of_cameras
from calibproj.formats.jsonio import atomic_write_bytes, atomic_write_text
from calibproj.report import figures
from calibproj.report.data import CameraView, camera_views
from calibproj.report.scene_view import scene_view_html
from calibproj.formats.provenance import read_provenance
from calibproj.selfcal.lenses import FILE_NAME as SELF_CALIBRATION_FILE
from calibproj.formats.results import (CHECK_FILE, DETECT_REPORT_FILE, EVALUATION_FILE, TRACKS_FILE, UNCERTAINTY_FILE,
                               intrinsics_source, load_results)
from calibproj.formats.tracks import Tracks
from calibproj.version import __version__

logger = logging.getLogger(__name__)

REPORT_FILE = "report.html"
FIGURES_DIR = "report"

STYLE = """
body { font-family: sans-serif; margin: 2em auto; max-width: 1200px; padding: 0 1em; color: #222;
       line-height: 1.4; }
h1 { margin-bottom: 0.2em; }
p.meta { color: #555; margin-top: 0; }
.scroll { overflow-x: auto; -webkit-overflow-scrolling: touch; margin: 1em 0; }
table { border-collapse: collapse; }
th, td { border: 1px solid #ccc; padding: 0.3em 0.7em; text-align: right; }
th { background: #f0f0f0; }
td.name, th.name, .summary td, .pairs td { text-align: left; }
td.failed, td.weak { color: #c0392b; text-align: left; font-weight: bold; }
td.code { font-family: monospace; text-align: left; word-break: break-all; }
img { max-width: 100%; height: auto; display: block; margin: 0.5em 0; }
figure { margin: 0.5em 0; }
.grid { display: grid; grid-template-columns: repeat(auto-fit, minmax(320px, 1fr)); gap: 0.5em 1em; }
p.failed, p.warning { color: #c0392b; font-weight: bold; }
div.warnings { border-left: 4px solid #c0392b; background: #fdf2f0; padding: 0.3em 1em; }
div.headline { border-left: 4px solid #2b7bba; background: #f2f7fc; padding: 0.3em 1em; margin: 1em 0; }
div.headline li.weak, div.headline li.failed { color: #c0392b; font-weight: bold; }
section.camera { border-top: 1px solid #ddd; margin-top: 1.5em; }
@media print {
  body { max-width: none; margin: 0; font-size: 10pt; }
  .scroll { overflow: visible; }
  table { font-size: 8pt; width: 100%; }
  th, td { padding: 0.15em 0.3em; word-break: break-word; }
  img { page-break-inside: avoid; }
  section.camera, figure, table, div.headline { page-break-inside: avoid; }
  h2, h3 { page-break-after: avoid; }
  div.interactive { display: none; }  /* the static views below print instead */
}
div.maps { display: flex; flex-wrap: wrap; gap: 0.5em; }
div.maps figure { flex: 1 1 300px; margin: 0; }
@media (max-width: 600px) {
  body { margin: 0.5em auto; padding: 0 0.5em; font-size: 15px; }
  th, td { padding: 0.25em 0.4em; }
  h1 { font-size: 1.5em; }
}
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
        results_dir: a folder written by ``calibproj calibrate`` (``camera_poses.json``, ...;
            ``detect_report.json``, ``provenance.json`` and ``evaluation.json`` are shown
            when present).
        tracks: the tracks the calibration was made from, ``Tracks`` or ``tracks.json``;
            ``None`` reads ``<results_dir>/tracks.json``.
        intrinsics: per-camera intrinsics or their folder; ``None`` reads
            ``<results_dir>/intrinsics``.
        dpi: resolution of the plots.
    """
    results_dir = Path(results_dir)
    calibration = load_results(results_dir)
    if tracks is None:
        tracks = results_dir / TRACKS_FILE
    tracks = tracks if isinstance(tracks, Tracks) else Tracks.read(tracks)
    names = [*calibration.metrics, *calibration.poses, *calibration.failed, *tracks.camera_names]
    # A camera whose intrinsics file is bad is drawn without it; the others are not held up.
    intrinsics, unusable = intrinsics_of_cameras(intrinsics_source(results_dir, intrinsics), names)
    for name, reason in unusable.items():
        logger.warning("report: camera %s is drawn without intrinsics (%s)", name, reason)
    views = camera_views(calibration, tracks, intrinsics)
    inputs = ReportInputs(detect_report=_optional_json(results_dir / DETECT_REPORT_FILE, "sync and detection"),
                          provenance=read_provenance(results_dir),
                          evaluation=_optional_json(results_dir / EVALUATION_FILE, "evaluation"),
                          self_calibration=_optional_json(results_dir / SELF_CALIBRATION_FILE, "self-calibration"),
                          check=_optional_json(results_dir / CHECK_FILE, "check"),
                          uncertainty=_optional_json(results_dir / UNCERTAINTY_FILE, "expected 3D error"))
    scene, cameras = draw_plots(calibration, views, dpi, _thumbnails(results_dir, inputs.detect_report))
    maps = uncertainty_plots(inputs.uncertainty, calibration, views, dpi)
    sync = sync_plots(inputs.detect_report, dpi)
    folder = results_dir / FIGURES_DIR
    for plot in [*scene, *maps, *sync, *(plot for plots in cameras.values() for plot in plots)]:
        atomic_write_bytes(folder / plot.file_name, plot.png)
    path = results_dir / REPORT_FILE
    interactive = scene_view_html(calibration, views) if calibration.poses else ""
    atomic_write_text(path, render_page(calibration, views, scene, cameras, inputs, sync, maps, interactive))
    logger.info("report written: %s (%.1f MB)", path, path.stat().st_size / 1e6)
    return path


@dataclass(frozen=True)
class ReportInputs:
    """What the report shows beyond the calibration: each a parsed JSON body, or None."""

    detect_report: dict | None = None
    provenance: dict | None = None
    evaluation: dict | None = None
    self_calibration: dict | None = None
    check: dict | None = None  # check.json of a folder `calibproj check --out` repaired
    uncertainty: dict | None = None  # uncertainty.json


@dataclass(frozen=True, eq=False)  # numpy field
class Thumbnail:
    """A grey frame of a camera's video (``frames/<camera>.png``) and what it shows."""

    image: np.ndarray
    scale: float  # thumbnail pixels per video pixel
    array: int | None  # the projected array in it


def draw_plots(calibration: Calibration, views: list[CameraView], dpi: int,
               thumbnails: Mapping[str, Thumbnail] | None = None) -> tuple[list[Plot], dict[str, list[Plot]]]:
    """The scene plots, and the plots of each camera (by name)."""
    scene = [Plot("errors.png", "Fit residual per camera (the calibration's own observations)",
                  figures.error_bars(views, dpi))]
    if calibration.poses:
        scene.append(Plot("scene_3d.png", "Cameras, floor and points", figures.scene_3d(calibration, views, dpi)))
        scene.append(Plot("scene_views.png", "Top and side views", figures.scene_views(calibration, views, dpi)))
    stems = safe_file_names([v.name for v in views], prefix="camera_", suffix="")
    thumbnails = thumbnails or {}
    cameras = {}
    for view in views:
        stem = stems[view.name]
        plots = []
        thumbnail = thumbnails.get(view.name)
        if thumbnail is not None:
            plots.append(Plot(f"{stem}_frame.png", f"{view.name}: a frame with its detections",
                              figures.camera_detections(view, thumbnail.image, thumbnail.scale, thumbnail.array,
                                                        dpi)))
        plots += [
            Plot(f"{stem}_errors.png", f"{view.name}: fit residuals", figures.camera_errors(view, dpi)),
            Plot(f"{stem}_residuals.png", f"{view.name}: residuals over the image",
                 figures.camera_residuals(view, dpi)),
            Plot(f"{stem}_coverage.png", f"{view.name}: coverage of the image", figures.camera_coverage(view, dpi)),
        ]
        cameras[view.name] = plots
    return scene, cameras


def uncertainty_plots(document: dict | None, calibration: Calibration, views: list[CameraView],
                      dpi: int) -> list[Plot]:
    """The maps of the expected 3D error, when uncertainty.json holds them (one that does
    not hold what the maps need is passed over, with a warning)."""
    if not document or not calibration.poses:
        return []
    try:
        maps = figures.uncertainty_maps(document, calibration, views, dpi)
    except (KeyError, TypeError, ValueError, IndexError) as error:
        logger.warning("%s: its map is not drawn (%s)", UNCERTAINTY_FILE, error)
        return []
    return [Plot(f"uncertainty_{stem}.png", f"Expected 3D error at the {label}", png) for stem, label, png in maps]


def sync_plots(detect_report: dict | None, dpi: int) -> list[Plot]:
    """The brightness trace of each camera whose light codes were not found."""
    cameras = (detect_report or {}).get("cameras") or {}
    traces = {name: c for name, c in cameras.items() if isinstance(c, dict) and isinstance(c.get("brightness"), dict)}
    stems = safe_file_names(list(traces), prefix="sync_")
    plots = []
    for name, camera in traces.items():
        trace = camera["brightness"]
        values, step = trace.get("values"), trace.get("frames_per_value")
        if not isinstance(values, list) or not values or not isinstance(step, int) or step < 1:
            continue
        reason = str(camera.get("error", "sync failed"))
        plots.append(Plot(stems[name], f"{name}: brightness over the video (sync failed)",
                          figures.brightness_trace([v if isinstance(v, (int, float)) else np.nan for v in values],
                                                   step, reason, dpi)))
    return plots


def _thumbnails(results_dir: Path, detect_report: dict | None) -> dict[str, Thumbnail]:
    """The thumbnails the detect report names (missing or unreadable ones are skipped)."""
    import cv2

    out = {}
    for name, camera in ((detect_report or {}).get("cameras") or {}).items():
        entry = camera.get("thumbnail") if isinstance(camera, dict) else None
        if not isinstance(entry, dict) or not isinstance(entry.get("file"), str):
            continue
        path = results_dir / entry["file"]
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) if path.is_file() else None
        scale = entry.get("scale")
        if image is None or not isinstance(scale, (int, float)) or not scale > 0:
            logger.warning("%s: thumbnail of camera %s not read", path, name)
            continue
        array = entry.get("array")
        out[str(name)] = Thumbnail(image, float(scale), array if isinstance(array, int) else None)
    return out


# -- HTML -----------------------------------------------------------------------------------


def _optional_json(path: Path, what: str) -> dict | None:
    """A JSON file of the results that the report shows if present, or None (absent,
    or unreadable: the report then goes without that section and says why in the log)."""
    if not path.exists():
        return None
    try:
        body = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        logger.warning("%s: not read (%s); the report has no %s section", path, error, what)
        return None
    return body if isinstance(body, dict) else None


def render_page(calibration: Calibration, views: list[CameraView], scene: list[Plot],
                cameras: dict[str, list[Plot]], inputs: ReportInputs | None = None,
                sync: list[Plot] | None = None, maps: list[Plot] | None = None, interactive: str = "") -> str:
    inputs = inputs or ReportInputs()
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        "<title>calibproj calibration report</title>",
        f"<style>{STYLE}</style></head><body>",
        "<h1>Calibration report</h1>",
        _meta_line(inputs.provenance),
        headline(calibration, views, inputs.evaluation, inputs.uncertainty),
        _warnings(views, inputs.self_calibration),
        _scroll(_summary(calibration, views, inputs.provenance)),
        *(["<h2>Check against the stored calibration</h2>", check_table(inputs.check, calibration.unit)]
          if inputs.check else []),
        "<h2>Cameras</h2>",
        "<p>Fit residual: reprojection error of the observations the calibration was made from "
        "(inliers). It measures how well the model fits, not how accurate the pose is: a camera "
        "with few points fits them closely. &sigma;: one standard deviation from the bundle "
        "adjustment's covariance, worst axis, relative to the first camera of the registration.</p>",
        _scroll(_camera_table(views, calibration.unit, reference_camera(calibration))),
        *(['<h2 id="expected-error">Expected 3D error</h2>', EXPECTED_ERROR_NOTE,
           _scroll(projection_table(inputs.uncertainty)),
           *([f'<div class="maps">{"".join(map(_figure, maps))}</div>', MAPS_NOTE] if maps else [])]
          if inputs.uncertainty else []),
        *(["<h2>Evaluation on independent points</h2>", evaluation_table(inputs.evaluation)]
          if inputs.evaluation else []),
        "<h2>Positions and intrinsics</h2>",
        _scroll(numbers_table(calibration, views)),
        *(["<h2>Intrinsics refined from the projection</h2>", self_calibration_table(inputs.self_calibration)]
          if inputs.self_calibration else []),
        *(["<h2>Sync and detection</h2>", _scroll(sync_table(inputs.detect_report)), SYNC_NOTE,
           *map(_figure, sync or [])]
          if inputs.detect_report else []),
        '<h2 id="scene">Scene</h2>',
        *([f'<div class="interactive">{interactive}<p><small>Cameras, frusta, floor, planes and points: drag to '
           'turn, scroll to zoom, click a name to hide it.</small></p></div>'] if interactive else []),
        *(_figure(plot) for plot in scene),
        "<h2>Per camera</h2>",
        *(_camera_section(view, cameras[view.name]) for view in views),
        *(["<h2>Provenance</h2>", _scroll(provenance_table(inputs.provenance))] if inputs.provenance else []),
        f"<p><small>calibproj {html.escape(__version__)}</small></p>",
        "</body></html>",
    ]
    return "\n".join(parts) + "\n"


def _scroll(table: str) -> str:
    """A table that scrolls sideways on a narrow screen instead of widening the page."""
    return f'<div class="scroll">{table}</div>'


def _meta_line(provenance: dict | None) -> str:
    if not provenance:
        return '<p class="meta">No provenance recorded (results not written by calibproj calibrate).</p>'
    created = html.escape(str(provenance.get("created", "?")))
    version = html.escape(str(provenance.get("calibproj", "?")))
    return f'<p class="meta">Made {created} with calibproj {version}; see Provenance at the end.</p>'


def headline(calibration: Calibration, views: list[CameraView], evaluation: dict | None,
             uncertainty: dict | None = None) -> str:
    """The first screen's answer to "is every camera OK, and how accurate is it?": how
    many cameras are calibrated, the expected 3D error at the projection's centre and
    over the working volume, the evaluation's success when there is one, and per camera
    its status with its sigma or its reason."""
    registered = sum(1 for view in views if view.registered)
    rates = (evaluation or {}).get("success_rate") or {}
    success = (f"; on independent points {html.escape(str(rates['0.5']))} % of the cameras within 0.5 px"
               if "0.5" in rates else "")
    items = [_status_item(calibration, view) for view in views]
    return (f'<div class="headline"><p><b>{registered} of {len(views)} cameras calibrated</b>{success}.</p>'
            f'{expected_error_line(uncertainty, calibration.unit)}<ul>{"".join(items)}</ul></div>')


EXPECTED_ERROR_NOTE = (
    "<p>From the final bundle adjustment's joint covariance of the poses (cross terms included) and each "
    "camera's noise: how far a point triangulated by the cameras that see it may lie from where it is "
    "(1 sigma, worst axis), and how far a point of the working volume may project from where the "
    "calibration puts it in each camera's image. Relative to the reference camera, whose pose and height "
    "(free model: distance to the farthest camera) the bundle adjustment held. Any point's figure: "
    "<code>calibproj.triangulation_uncertainty(RESULTS, points)</code>.</p>")


MAPS_NOTE = ("<p>The expected 3D error of a point the cameras triangulate, over the floor at three heights, "
             "on one colour scale; blank where fewer than two cameras see.</p>")


def projection_table(document: dict | None) -> str:
    """Per camera of uncertainty.json: its noise and how far the volume's points it sees
    may project (median, largest)."""
    rows = []
    for camera in (document or {}).get("cameras") or []:
        if not isinstance(camera, dict):
            continue
        sigma = camera.get("projection_sigma_px") or {}
        rows.append("<tr>" + "".join(f"<td>{cell}</td>" for cell in (
            html.escape(str(camera.get("name", "?"))), _number(camera.get("noise_px"), 3),
            html.escape(str(camera.get("cells_seen", "-"))), _number(sigma.get("median"), 3),
            _number(sigma.get("max"), 3))) + "</tr>")
    return ("<table><tr><th>camera</th><th>noise [px]</th><th>map cells seen</th>"
            "<th>projection &sigma; median [px]</th><th>projection &sigma; max [px]</th></tr>"
            + "".join(rows) + "</table>")


def expected_error_line(document: dict | None, unit: str) -> str:
    """The expected 3D error of a triangulated point at the table above the projection's
    centre and over the volume (uncertainty.json), or nothing without the file."""
    centre = (document or {}).get("centre") or {}
    volume = (document or {}).get("volume") or {}
    if not isinstance(centre.get("sigma"), (int, float)) or not isinstance(volume.get("median_sigma"), (int, float)):
        return ""
    length = (lambda v: f"{1000.0 * v:.1f} mm") if unit == "m" else (lambda v: f"{v:.3g} units")
    p90 = volume.get("p90_sigma")
    spread = f", 90 % of it under {length(p90)}" if isinstance(p90, (int, float)) else ""
    cameras = ", ".join(html.escape(str(name)) for name in centre.get("cameras") or [])
    reference = html.escape(str((document.get("gauge") or {}).get("reference_camera", "")))
    return (f'<p><b>Expected 3D error {length(centre["sigma"])}</b> (1 sigma, worst axis) for a point at the '
            f'table above the projection\'s centre, triangulated by {cameras}; over the working volume '
            f'(floor to 2 m) {length(volume["median_sigma"])} at the median{spread}. Relative to the reference '
            f'camera {reference}; <a href="#expected-error">maps below</a>.</p>')


def _status_item(calibration: Calibration, view: CameraView) -> str:
    name, status, m = html.escape(view.name), calibration.status(view.name), view.metrics
    if status == "failed":
        return f'<li class="failed">Camera {name} FAILED: {html.escape(view.failure or "not registered")}</li>'
    if status == "reference":
        return f"<li>{name}: the reference (the others' sigmas are relative to it)</li>"
    metric = calibration.unit == "m"
    centre = None if m is None or m.centre_sigma is None else m.centre_sigma * (1e3 if metric else 1.0)
    sigmas = (f"rotation {_number(m.rotation_sigma_deg, 4)} deg, centre {_number(centre, 2 if metric else 5)} "
              f"{'mm' if metric else 'units'} (1 &sigma;)") if m is not None else "no sigma"
    if status == "weak":
        return (f'<li class="weak">Camera {name} is WEAK: {sigmas} from {m.inliers} observations; a short '
                f"extra projection for it helps (<code>calibproj generate --densify</code>)</li>")
    return f"<li>{name}: ok, {sigmas}</li>"


def _warnings(views: list[CameraView], self_calibration: dict | None = None) -> str:
    """What the headline does not say: intrinsics the self-calibration could not vouch for."""
    reasons = _weak_lenses(self_calibration)
    lines = [f"<p class=\"warning\">Camera {html.escape(view.name)} is WEAK: {html.escape(reasons[view.name])}; "
             "its pose rests on intrinsics nobody checked.</p>"
             for view in views if view.registered and view.name in reasons]
    return f'<div class="warnings">{"".join(lines)}</div>' if lines else ""


def _weak_lenses(document: dict | None) -> dict[str, str]:
    """Cameras of ``self_calibration.json`` made weak by it, with why (``weak_reason``)."""
    cameras = (document or {}).get("cameras")
    if not isinstance(cameras, dict):
        return {}
    return {str(name): camera["weak_reason"] for name, camera in cameras.items()
            if isinstance(camera, dict) and isinstance(camera.get("weak_reason"), str)}


def _summary(calibration: Calibration, views: list[CameraView], provenance: dict | None) -> str:
    registered = sum(1 for v in views if v.registered)
    unit = "metres" if calibration.unit == "m" else "arbitrary (first camera at height 1)"
    floor = f"{calibration.floor_rms:.4g}" + (" m" if calibration.unit == "m" else "")
    if calibration.model == "coplanar" and calibration.floor_rms < 1e-9:  # rounding, not a measurement
        floor = ("0: kept flat (no relief beyond what the observations' noise explains, or --floor-relief 0): "
                 "the floor's points lie on the floor plane")
    elif calibration.model == "coplanar":
        floor += " (the floor's relief, estimated: its points leave the plane by it alone)"
    rows = [
        ("registered cameras", f"{registered} of {len(views)}"),
        ("model", calibration.model),
        ("unit", unit),
        ("scale from", _scale_source(calibration, provenance)),
        ("points", str(len(calibration.points))),
        ("points' RMS distance to the floor", floor),
        *((f"plane {k + 1} besides the floor", plane_text(plane, calibration.unit))
          for k, plane in enumerate(calibration.planes)),
        ("registration order", ", ".join(calibration.registration_order) or "-"),
    ]
    body = "".join(f"<tr><th class=\"name\">{html.escape(k)}</th><td>{html.escape(v)}</td></tr>" for k, v in rows)
    return f'<table class="summary">{body}</table>'


def plane_text(plane: Plane, unit: str) -> str:
    """A plane the projection landed on besides the floor (a table top), in words."""
    normal = np.asarray(plane.normal, dtype=float)
    tilt = float(np.degrees(np.arccos(np.clip(abs(normal[2]) / max(np.linalg.norm(normal), 1e-12), -1.0, 1.0))))
    suffix = " m" if unit == "m" else " units"
    where = (f"{_number(plane.offset, 4)}{suffix} above the floor" if tilt < 5.0
             else f"tilted {tilt:.1f} deg from the floor")
    return f"{where}, {plane.points} points (e.g. a table left in the projection)"


def _scale_source(calibration: Calibration, provenance: dict | None) -> str:
    scale = (provenance or {}).get("scale")
    if isinstance(scale, dict) and scale.get("measurement"):
        if scale.get("error"):
            return f"{scale['measurement']}: not applied ({scale['error']})"
        factor = scale.get("metres_per_unit")
        return f"{scale['measurement']}" + (f" ({factor:.6g} m per unit)" if isinstance(factor, (int, float)) else "")
    return "unknown (no provenance)" if calibration.unit == "m" and not provenance else "no measurement"


def reference_camera(calibration: Calibration) -> str | None:
    """The first registered camera: the others' sigmas are relative to it."""
    return calibration.registration_order[0] if calibration.registration_order else None


def _camera_table(views: list[CameraView], unit: str, reference: str | None) -> str:
    centre_unit = "mm" if unit == "m" else "units"
    header = ("<tr><th class=\"name\">camera</th><th>fit residual mean [px]</th><th>std [px]</th>"
              "<th>observations</th><th>inliers</th><th>track &ge; 2 observations</th><th>view score</th>"
              f"<th>rotation &sigma; [deg]</th><th>centre &sigma; [{centre_unit}]</th></tr>")
    rows = [header]
    for view in views:
        name = f'<td class="name"><a href="#{_anchor(view.name)}">{html.escape(view.name)}</a></td>'
        if not view.registered:
            reason = html.escape(view.failure or "not registered")
            rows.append(f'<tr>{name}<td class="failed" colspan="8">FAILED: {reason}</td></tr>')
            continue
        m = view.metrics
        centre_sigma = None if m is None or m.centre_sigma is None else m.centre_sigma * (1e3 if unit == "m" else 1.0)
        # The reference's sigmas are 0 by construction: it is named instead.
        sigmas = (['<td class="name" colspan="2">reference (the others\' sigmas are relative to it)</td>']
                  if view.name == reference else
                  [f"<td>{_number(m.rotation_sigma_deg, 4) if m else '-'}</td>",
                   f"<td>{_number(centre_sigma, 2 if unit == 'm' else 5)}</td>"])
        cells = [_number(m.mean_px, 3), _number(m.std_px, 3), str(m.observations), str(m.inliers),
                 str(m.track2_observations), str(m.view_score)] if m else ["-"] * 6
        weak = (f'<tr><td></td><td class="weak" colspan="8">WEAK: rotation known to '
                f'{m.rotation_sigma_deg:.3f} deg (1 sigma); more points in its view help: '
                f'<code>calibproj generate --densify</code> plans a short extra projection for it</td></tr>'
                if m is not None and m.weak and m.rotation_sigma_deg is not None else "")
        rows.append(f"<tr>{name}" + "".join(f"<td>{c}</td>" for c in cells) + "".join(sigmas) + "</tr>" + weak)
    return "<table>" + "".join(rows) + "</table>"


def numbers_table(calibration: Calibration, views: list[CameraView]) -> str:
    """Per registered camera: its centre with 1-sigma, height, tilt from straight down,
    heading, and the intrinsics used."""
    metric = calibration.unit == "m"
    unit = "m" if metric else "units"
    header = (f"<tr><th class=\"name\">camera</th><th>x [{unit}]</th><th>y [{unit}]</th><th>height z [{unit}]</th>"
              f"<th>centre &sigma; [{'mm' if metric else unit}]</th><th>tilt from down [deg]</th>"
              "<th>heading [deg]</th><th>fx [px]</th><th>fy [px]</th><th>cx [px]</th><th>cy [px]</th>"
              "<th>k1</th><th>k2</th><th>image [px]</th></tr>")
    rows = [header]
    for view in views:
        if not view.registered:
            continue
        R, t = view.pose
        centre = -R.T @ t
        axis = R[2]  # optical axis in the floor frame (third row of R)
        tilt = float(np.degrees(np.arccos(np.clip(-axis[2], -1.0, 1.0))))
        heading = float(np.degrees(np.arctan2(axis[1], axis[0])))
        sigma = view.metrics.centre_sigma if view.metrics is not None else None
        cells = [_number(c, 4) for c in centre] + [
            _number(None if sigma is None else sigma * (1e3 if metric else 1.0), 2 if metric else 5),
            _number(tilt, 2), _number(heading, 1), *_intrinsics_cells(view)]
        rows.append(f'<tr><td class="name">{html.escape(view.name)}</td>'
                    + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    return "<table>" + "".join(rows) + "</table>"


def _intrinsics_cells(view: CameraView) -> list[str]:
    camera = view.intrinsics
    if camera is None:
        return ["-"] * 7
    K, dist = np.asarray(camera.K, dtype=float), np.asarray(camera.dist, dtype=float).ravel()
    size = view.image_size()
    image = f"{size[0]:.0f} x {size[1]:.0f}" if size is not None else "-"
    k1, k2 = (_number(dist[i], 4) if dist.size > i else "-" for i in (0, 1))
    return [_number(K[0, 0], 1), _number(K[1, 1], 1), _number(K[0, 2], 1), _number(K[1, 2], 1), k1, k2, image]


def evaluation_table(document: dict) -> str:
    """``evaluation.json`` (``calibproj evaluate --save``): success rates and per-camera errors."""
    rates = document.get("success_rate") or {}
    line = ", ".join(f"{html.escape(str(v))} % under {html.escape(str(k))} px" for k, v in rates.items())
    source = document.get("tracks")
    rows = ["<tr><th class=\"name\">camera</th><th>mean [px]</th><th>std [px]</th><th>observations</th></tr>"]
    for name, camera in (document.get("cameras") or {}).items():
        camera = camera if isinstance(camera, dict) else {}
        failure = (document.get("failures") or {}).get(name)
        cell = f'<td class="name">{html.escape(str(name))}</td>'
        if camera.get("mean_px") is None:
            rows.append(f'<tr>{cell}<td class="failed" colspan="3">FAILED: {html.escape(str(failure or "-"))}'
                        "</td></tr>")
            continue
        rows.append(f"<tr>{cell}<td>{_number(camera.get('mean_px'), 3)}</td><td>{_number(camera.get('std_px'), 3)}"
                    f"</td><td>{html.escape(str(camera.get('n', '-')))}</td></tr>")
    intro = ("<p>Reprojection error on points that took no part in the calibration"
             + (f" ({html.escape(str(source))})" if source else "") + f": success {line}.</p>")
    return intro + _scroll("<table>" + "".join(rows) + "</table>")


def check_table(document: dict, unit: str) -> str:
    """``check.json`` (``calibproj check --out``): which cameras changed, by how much (with
    the sigma of the change), and the residuals before and after the repair."""
    metric = unit == "m"
    rows = ["<tr><th class=\"name\">camera</th><th class=\"name\">status</th><th>rotation [deg]</th>"
            f"<th>centre [{'mm' if metric else html.escape(unit)}]</th><th>focal [%]</th>"
            "<th>working volume moved [px]</th><th>residual before &rarr; after [px]</th>"
            "<th class=\"name\">why</th></tr>"]
    cameras = document.get("cameras") if isinstance(document.get("cameras"), dict) else {}
    scale = 1000.0 if metric else 1.0
    for name, camera in cameras.items():
        camera = camera if isinstance(camera, dict) else {}
        status = str(camera.get("status", "-"))
        css = "failed" if status in ("moved", "rezoomed") else ""

        def change(value: str, sigma: str, factor: float = 1.0, digits: int = 3) -> str:
            if camera.get(value) is None:
                return "-"
            spread = _number((camera.get(sigma) or 0) * factor, digits)
            return f"{_number(camera[value] * factor, digits)} &plusmn; {spread}"

        rows.append(
            f'<tr><td class="name">{html.escape(str(name))}</td><td class="name {css}">{html.escape(status)}</td>'
            f"<td>{change('rotation_change_deg', 'rotation_sigma_deg')}</td>"
            f"<td>{change('centre_change', 'centre_sigma', scale, 2)}</td>"
            f"<td>{change('focal_change', 'focal_sigma', 100.0, 2)}</td>"
            f"<td>{_number(camera.get('volume_shift_px'), 2)}</td>"
            f"<td>{_number(camera.get('rms_before_px'), 3)} &rarr; {_number(camera.get('rms_after_px'), 3)}</td>"
            f'<td class="name">{html.escape(str(camera.get("reason", "")))}</td></tr>')
    intro = (f"<p>{html.escape(str(document.get('message', '')))}. The moved and re-zoomed cameras were fitted "
             "again to the calibrated points (every other camera and the floor held); the others keep the "
             "stored calibration.</p>")
    return intro + _scroll("<table>" + "".join(rows) + "</table>")


def self_calibration_table(document: dict) -> str:
    """``self_calibration.json`` (``--refine-intrinsics``): per camera what was refined,
    with its uncertainty, and what kept its given value, with why."""
    rows = ["<tr><th class=\"name\">camera</th><th>focal given &rarr; found [px]</th><th>&sigma; focal</th>"
            "<th>k1 given &rarr; found</th><th>&sigma; distortion [px]</th><th>coverage</th><th>noise [px]</th>"
            "<th>pattern left [px]</th>"
            "<th class=\"name\">refined</th><th class=\"name\">kept as given; warnings</th></tr>"]
    cameras = document.get("cameras") if isinstance(document.get("cameras"), dict) else {}
    for name, camera in cameras.items():
        camera = camera if isinstance(camera, dict) else {}
        given = camera.get("given") if isinstance(camera.get("given"), dict) else {}
        found = camera.get("result") if isinstance(camera.get("result"), dict) else {}
        focal_sigma = camera.get("focal_sigma")
        relative = (f" ({100.0 * focal_sigma / found['focal']:.3f} %)"
                    if isinstance(focal_sigma, (int, float)) and isinstance(found.get("focal"), (int, float))
                    and found["focal"] else "")
        held = camera.get("held") if isinstance(camera.get("held"), dict) else {}
        refined = camera.get("refined") if isinstance(camera.get("refined"), list) else []
        misfit = camera.get("misfit") if isinstance(camera.get("misfit"), str) else None
        pattern_class = ' class="weak"' if misfit else ""
        kept = "<br>".join([*(html.escape(f"{k}: {v}") for k, v in held.items()),
                            *([html.escape(misfit)] if misfit else [])]) or "-"
        rows.append(
            f'<tr><td class="name">{html.escape(str(name))}</td>'
            f"<td>{_number(given.get('focal'), 1)} &rarr; {_number(found.get('focal'), 1)}</td>"
            f"<td>{_number(focal_sigma, 2)}{relative}</td>"
            f"<td>{_number(given.get('k1'), 4)} &rarr; {_number(found.get('k1'), 4)}</td>"
            f"<td>{_number(camera.get('distortion_sigma_px'), 3)}</td>"
            f"<td>{_percent(camera.get('coverage'))}</td><td>{_number(camera.get('noise_px'), 3)}</td>"
            f"<td{pattern_class}>{_number(camera.get('systematic_px'), 3)}</td>"
            f'<td class="name">{html.escape(", ".join(map(str, refined)) or "-")}</td>'
            f'<td class="name">{kept}</td></tr>')
    intro = ("<p>Each camera's lens was refined with the poses from the floor points it shares with the "
             "others, starting from the intrinsics given. An entry kept as given either did not improve "
             "the fit, or the data do not determine it (its 1 &sigma; is given). Coverage: how far towards "
             "the image corners the camera saw the floor; beyond that the refined distortion is an "
             "extrapolation. Pattern left: the smooth part of the camera's residuals (a quadratic field over "
             "the image); a large one means an entry kept at a wrong value or a lens model that does not "
             "fit, and the camera is flagged weak.</p>")
    return intro + _scroll("<table>" + "".join(rows) + "</table>")


def _percent(value: Any) -> str:
    return f"{100.0 * value:.0f} %" if isinstance(value, (int, float)) and math.isfinite(value) else "-"


def provenance_table(provenance: dict) -> str:
    """When, how and from what the results were made (``provenance.json``)."""
    inputs = provenance.get("inputs") or {}
    command = provenance.get("command")
    rows = [
        ("made", provenance.get("created")),
        ("calibproj", provenance.get("calibproj")),
        ("command", " ".join(shlex.quote(str(a)) for a in command) if isinstance(command, list)
         else "Python API call"),
        ("Python, platform", f"{provenance.get('python')}, {provenance.get('platform')}"),
        ("markers", provenance.get("markers") or "-"),
        ("model", provenance.get("model")),
        ("source", _identity(inputs.get("source"))),
        ("sequence", _identity(inputs.get("sequence"))),
        ("intrinsics", _identity(inputs.get("intrinsics"))),
        *((f"video {name}", _identity(entry)) for name, entry in (inputs.get("videos") or {}).items()),
    ]
    body = "".join(f'<tr><th class="name">{html.escape(str(k))}</th><td class="code">{html.escape(str(v))}</td></tr>'
                   for k, v in rows)
    return f'<table class="pairs">{body}</table>'


def _identity(entry: Any) -> str:
    if not isinstance(entry, dict):
        return "-" if entry is None else str(entry)
    details = [f"{entry['bytes']} bytes" if "bytes" in entry else None,
               f"sha256 {entry['sha256']}" if "sha256" in entry else None,
               f"modified {entry['modified']}" if "modified" in entry else None]
    extra = ", ".join(d for d in details if d)
    return f"{entry.get('path', '?')}" + (f" ({extra})" if extra else "")


# What a reader of the sync table asks first: why one camera's offset is known to a
# millisecond and another's only to a frame.
SYNC_NOTE = (
    "<p>Offset: where the camera's first frame falls on the projection's timeline, from the "
    "light codes at its start and end. Its 1&sigma; is small (a fraction of a frame) when the "
    "camera's frames fall at many phases of the projector's frames, so that some frames catch a "
    "light change during their exposure: a frame rate that differs slightly from the projector's "
    "(29.97 against 30 fps) or a long exposure. A camera whose frames keep a fixed phase to the "
    "projector's (the same frame rate, a multiple of it, or a small ratio) with a short exposure "
    "never sees a light change within a frame: any offset within about a frame gives the same "
    "video, hence a 1&sigma; of about a frame. The frame picking allows for it (frames near a "
    "pattern change are not used), so it does not reach the poses; a known exposure "
    "(<code>--exposure</code>) narrows it.</p>")


def sync_table(detect_report: dict) -> str:
    """Per camera: its sync to the projector with uncertainties, its frames and what
    the markers of each scale gave (``detect_report.json``'s values)."""
    header = ("<tr><th class=\"name\">camera</th><th>offset [s] &plusmn; 1&sigma;</th><th>drift [ppm]</th>"
              "<th>exposure [frames]</th><th>readout [ms] &plusmn; 1&sigma;</th>"
              "<th>frames decoded / dropped / duplicated</th><th>patterns used / dropped / missing</th>"
              "<th>markers kept per scale</th><th>detections dropped as inconsistent</th></tr>")
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
        offset += f" &plusmn; {_number(offset_sigma / fps, 4)}"
    readout = "-"
    if sync.get("readout_s") is not None:
        readout_sigma = 1e3 * (sync.get("readout_sigma_s") or 0.0)
        readout = f"{_number(1e3 * sync['readout_s'], 2)} &plusmn; {_number(readout_sigma, 2)}"
    used = patterns.get("whole_frame", 0) + patterns.get("in_regions", 0)
    kept = ", ".join(f"{scale.get('kept', 0)} at {scale.get('scale', '?'):g}x" for scale in camera.get("scales", []))
    return [offset, _number(sync.get("drift_ppm"), 1), _number(sync.get("exposure_frames"), 2), readout,
            f"{frames.get('decoded', '-')} / {frames.get('dropped', '-')} / {frames.get('duplicated', '-')}",
            f"{used} / {patterns.get('dropped', '-')} / {patterns.get('missing', '-')}", kept,
            str(camera.get("detections_inconsistent", "-"))]


def _camera_section(view: CameraView, plots: list[Plot]) -> str:
    title = f'<section class="camera" id="{_anchor(view.name)}"><h3>{html.escape(view.name)}</h3>'
    status = "" if view.registered else f'<p class="failed">FAILED: {html.escape(view.failure or "")}</p>'
    grid = '<div class="grid">' + "".join(_figure(plot) for plot in plots) + "</div>"
    return title + status + grid + "</section>"


def _figure(plot: Plot) -> str:
    data = base64.b64encode(plot.png).decode("ascii")
    caption = html.escape(plot.caption)
    below = f"<figcaption>{caption}</figcaption>"
    return f'<figure><img alt="{caption}" src="data:image/png;base64,{data}">{below}</figure>'


def _anchor(name: str) -> str:
    """A camera's fragment id: safe in a URL, unique among the cameras."""
    return "camera-" + re.sub(r"[^A-Za-z0-9_-]", "_", name) + "-" + hashlib.sha1(name.encode()).hexdigest()[:6]


def _number(value: Any, digits: int) -> str:
    """A number with ``digits`` decimals; "-" for None and anything not a number (the
    JSON files shown may have been edited by hand)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        return "-"
    text = f"{value:.{digits}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text  # no "-0.000"
