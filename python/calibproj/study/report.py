"""The marker study's outputs: ``study.json`` (every measurement and the summary) and
``study.html`` (plots, the recommendation table and the calibrations), self-contained."""

from __future__ import annotations

import base64
import html
import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from calibproj.formats.jsonio import atomic_write_bytes, atomic_write_text, write_json
from calibproj.report.figures import DEFAULT_DPI, png_bytes
from calibproj.report.page import STYLE
from calibproj.study.images import IMAGE_SIZE
from calibproj.version import __version__

STUDY_KIND = "study"
STUDY_MAJOR = 1
SMALL_PX = 15.0  # "small markers": the side the sweeps always measure
LARGE_PX = 20.0  # centre accuracy is judged from this side up
FOUND_SHARE = 0.9
SMALL_MARGIN = 0.1  # shares of markers found closer than this do not tell families apart


def mean_by(rows: list[dict], family: str, sweep: str, x: str, y: str) -> tuple[np.ndarray, np.ndarray]:
    """Mean of ``y`` over seeds at each ``x`` of one family's sweep (NaN-aware)."""
    groups: dict[float, list[float]] = defaultdict(list)
    for row in rows:
        if row["family"] == family and row["sweep"] == sweep:
            # None: a measurement study.json stores as null (NaN, no marker found).
            groups[float(row[x])].append(math.nan if row[y] is None else float(row[y]))
    xs = np.array(sorted(groups))
    with np.errstate(all="ignore"):
        ys = np.array([np.nanmean(groups[v]) if np.any(np.isfinite(groups[v])) else np.nan for v in xs])
    return xs, ys


def family_summary(images: list[dict], calibrations: list[dict], family: str) -> dict[str, Any]:
    """What the recommendation table shows of one family."""
    sides, rates = mean_by(images, family, "side", "side_px", "rate")
    _, errors = mean_by(images, family, "side", "side_px", "centre_rms_px")
    reached = [float(s) for s, r in zip(sides, rates) if r >= FOUND_SHARE]
    small = rates[sides == SMALL_PX]
    large = errors[(sides >= LARGE_PX) & np.isfinite(errors)]
    own = [r for r in images if r["family"] == family]
    clean = [c for c in calibrations if c["family"] == family and c["condition"] == "clean"]
    return {
        "smallest_side_px_found_90": min(reached) if reached else None,
        "found_share_at_15px": float(small[0]) if len(small) else None,
        "centre_rms_px_at_20px_or_more": float(np.sqrt(np.mean(large ** 2))) if len(large) else None,
        "ms_per_frame": float(np.median([r["ms"] for r in own])) if own else None,
        "false_detections": int(sum(r["false"] for r in own)),
        "rotation_rmse_deg_clean": _first(clean, "rotation_rmse_deg"),
        "msm_centre_rms_px_clean": _first(clean, "msm_centre_rms_px"),
        "eval_mean_px_clean": _first(clean, "eval_mean_px"),
    }


def _finite(value: Any) -> Any:
    """The value with NaN (no measurement) as null: JSON has no NaN."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return None if _nan(value) else value


def _best_at_small(resolve: dict[str, float], at_small: dict[str, float]) -> str | None:
    """The family that resolves the smallest markers: the smallest side with 90 % found,
    then the most found at SMALL_PX; None when no family stands out by either (less than
    SMALL_MARGIN apart at SMALL_PX)."""
    if len(resolve) >= 2 and len(set(resolve.values())) > 1:
        ordered = sorted(resolve, key=lambda f: (resolve[f], -at_small.get(f, 0.0)))
        if resolve[ordered[0]] < resolve[ordered[1]]:
            return ordered[0]
    if len(at_small) >= 2:
        ordered = sorted(at_small, key=at_small.get, reverse=True)
        if at_small[ordered[0]] - at_small[ordered[1]] >= SMALL_MARGIN:
            return ordered[0]
    return None


def _first(rows: list[dict], key: str) -> float | None:
    values = [r[key] for r in rows if r.get(key) is not None and not _nan(r[key])]
    return float(values[0]) if values else None


def _nan(value: Any) -> bool:
    return isinstance(value, float) and math.isnan(value)


def recommendation(summary: dict[str, dict]) -> list[str]:
    """Sentences drawn from the measurements: which family for small markers, which is
    faster, how accurate both are, and how the calibrations compare."""
    families = list(summary)
    lines = []
    resolve = {f: s["smallest_side_px_found_90"] for f, s in summary.items()
               if s["smallest_side_px_found_90"] is not None}
    at_small = {f: s["found_share_at_15px"] for f, s in summary.items() if s["found_share_at_15px"] is not None}
    small_best = _best_at_small(resolve, at_small)
    if small_best is not None:
        sides = ", ".join(f"{f} {v:g} px" for f, v in resolve.items())
        shares = ", ".join(f"{f} {100 * v:.0f} %" for f, v in at_small.items())
        lines.append(f"Small markers: {small_best} resolves the smallest (90 % of the markers found from: {sides}; "
                     f"found at {SMALL_PX:g} px: {shares}).")
    speed = {f: s["ms_per_frame"] for f, s in summary.items() if s["ms_per_frame"]}
    if len(speed) >= 2:
        fastest = min(speed, key=speed.get)
        slowest = max(speed, key=speed.get)
        ratio = speed[slowest] / speed[fastest]
        lines.append(f"Speed: {fastest} detects a frame in {speed[fastest]:.0f} ms, {ratio:.1f}x "
                     f"faster than {slowest} ({speed[slowest]:.0f} ms).")
    for family in families:
        error = summary[family]["centre_rms_px_at_20px_or_more"]
        merged = summary[family].get("msm_centre_rms_px_clean")
        if error is not None:
            lines.append(f"Centre error of {family}: single markers from {LARGE_PX:g} px up {error:.3f} px RMS"
                         + (f"; MSM centres in the calibrated room {merged:.3f} px" if merged is not None else "")
                         + ".")
    clean = {f: s["rotation_rmse_deg_clean"] for f, s in summary.items() if s["rotation_rmse_deg_clean"] is not None}
    if len(clean) >= 2:
        rotations = ", ".join(f"{f} {v:.4f} deg" for f, v in clean.items())
        lines.append(f"Calibration of the room (clean): {rotations}.")
    if small_best is not None and len(speed) >= 2:
        best_small = small_best
        fastest = min(speed, key=speed.get)
        if best_small != fastest:
            where = (f"90 % found from {resolve[best_small]:g} px" if best_small in resolve
                     else f"{100 * at_small[best_small]:.0f} % found at {SMALL_PX:g} px")
            lines.append(f"Choose {best_small} where cameras see the markers small ({where}: wide views, "
                         f"high mounts); {fastest} otherwise, for its speed.")
        else:
            lines.append(f"Choose {best_small}: it finds more small markers and is faster.")
    return lines


def write_study(out: Path, images: list[dict], calibrations: list[dict], families: tuple[str, ...],
                settings: dict[str, Any], dpi: int = DEFAULT_DPI) -> Path:
    """``study.json``, ``study.html`` and the plots as ``study/*.png`` in ``out``; the page's path."""
    summary = {f: family_summary(images, calibrations, f) for f in families}
    advice = recommendation(summary)
    write_json(out / "study.json", STUDY_KIND, STUDY_MAJOR, _finite(
               {"calibproj": __version__, "settings": settings, "summary": summary, "recommendation": advice,
                "images": images, "calibrations": calibrations}))
    plots = _plots(images, calibrations, families, dpi)
    for name, png in plots:
        atomic_write_bytes(out / "study" / name, png)
    page = out / "study.html"
    atomic_write_text(page, _page(summary, advice, plots, calibrations, settings))
    return page


def _plots(images: list[dict], calibrations: list[dict], families: tuple[str, ...],
           dpi: int) -> list[tuple[str, bytes]]:
    sweeps = [("rate_vs_side.png", "side", "side_px", "rate", "marker side [px]", "markers found"),
              ("error_vs_side.png", "side", "side_px", "centre_rms_px", "marker side [px]", "centre error RMS [px]"),
              ("rate_vs_blur.png", "blur", "blur_px", "rate", f"blur sigma [px] (markers {LARGE_PX:g} px)",
               "markers found"),
              ("rate_vs_noise.png", "noise", "noise_std", "rate",
               f"sensor noise [grey levels] (markers {LARGE_PX:g} px)", "markers found"),
              ("rate_vs_contrast.png", "light", "contrast", "rate",
               f"projector contrast, room light rising as it falls (markers {LARGE_PX:g} px)", "markers found")]
    plots = []
    for name, sweep, x, y, xlabel, ylabel in sweeps:
        figure = Figure(figsize=(6.0, 3.8))
        axes = figure.subplots()
        for family in families:
            xs, ys = mean_by(images, family, sweep, x, y)
            axes.plot(xs, ys, "o-", label=family)
        axes.set_xlabel(xlabel, fontsize=9)
        axes.set_ylabel(ylabel)
        if y == "rate":
            axes.set_ylim(-0.02, 1.02)
        else:
            axes.set_ylim(bottom=0.0)
        axes.grid(True, linewidth=0.3)
        axes.legend(fontsize=8)
        figure.tight_layout()
        plots.append((name, png_bytes(figure, dpi)))
    plots.append(("ms_per_frame.png", _speed(images, families, dpi)))
    if calibrations:
        plots.append(("calibrations.png", _calibration_bars(calibrations, families, dpi)))
    return plots


def _speed(images: list[dict], families: tuple[str, ...], dpi: int) -> bytes:
    figure = Figure(figsize=(6.0, 3.2))
    axes = figure.subplots()
    times = [np.array([r["ms"] for r in images if r["family"] == f] or [0.0]) for f in families]
    medians = np.array([np.median(t) for t in times])
    # Median with the quartiles as whiskers.
    spread = np.array([[m - np.percentile(t, 25), np.percentile(t, 75) - m] for m, t in zip(medians, times)]).T
    axes.barh(np.arange(len(families)), medians, xerr=spread, color="#2b7bba", capsize=3)
    axes.set_yticks(np.arange(len(families)), families)
    axes.set_xlabel(f"detection time per frame [ms] (one thread, {IMAGE_SIZE[0]}x{IMAGE_SIZE[1]})")
    axes.set_xlim(left=0.0)
    figure.tight_layout()
    return png_bytes(figure, dpi)


def _calibration_bars(calibrations: list[dict], families: tuple[str, ...], dpi: int) -> bytes:
    conditions = list(dict.fromkeys(c["condition"] for c in calibrations))
    figure = Figure(figsize=(6.0, 3.6))
    axes = figure.subplots()
    width = 0.8 / max(1, len(families))
    for k, family in enumerate(families):
        values = [_first([c for c in calibrations if c["family"] == family and c["condition"] == condition],
                         "rotation_rmse_deg") for condition in conditions]
        axes.bar(np.arange(len(conditions)) + k * width, [v if v is not None else 0.0 for v in values], width,
                 label=family)
    axes.set_xticks(np.arange(len(conditions)) + 0.4 - width / 2, conditions)
    axes.set_ylabel("rotation RMSE [deg]")
    axes.set_title("calibration against the truth (cameras not weak)", fontsize=10)
    axes.legend(fontsize=8)
    figure.tight_layout()
    return png_bytes(figure, dpi)


def _page(summary: dict[str, dict], advice: list[str], plots: list[tuple[str, bytes]], calibrations: list[dict],
          settings: dict[str, Any]) -> str:
    rows = ["<tr><th class=\"name\">family</th><th>smallest side with 90 % found [px]</th>"
            "<th>found at 15 px</th><th>centre RMS at &ge; 20 px [px]</th><th>ms per frame</th>"
            "<th>false detections</th><th>MSM centre RMS in the room, clean [px]</th>"
            "<th>rotation RMSE, clean [deg]</th><th>evaluation, clean [px]</th></tr>"]
    for family, s in summary.items():
        cells = [_cell(s["smallest_side_px_found_90"], "{:g}"), _cell(s["found_share_at_15px"], "{:.0%}"),
                 _cell(s["centre_rms_px_at_20px_or_more"], "{:.3f}"), _cell(s["ms_per_frame"], "{:.0f}"),
                 str(s["false_detections"]), _cell(s["msm_centre_rms_px_clean"], "{:.3f}"),
                 _cell(s["rotation_rmse_deg_clean"], "{:.4f}"),
                 _cell(s["eval_mean_px_clean"], "{:.3f}")]
        rows.append(f'<tr><td class="name">{html.escape(family)}</td>' + "".join(f"<td>{c}</td>" for c in cells)
                    + "</tr>")
    figures = "".join(
        f'<figure><img alt="{html.escape(name)}" src="data:image/png;base64,{base64.b64encode(png).decode()}">'
        f"<figcaption>{html.escape(name[:-4].replace('_', ' '))}</figcaption></figure>" for name, png in plots)
    calibration_rows = ["<tr><th class=\"name\">family</th><th class=\"name\">condition</th><th>registered</th>"
                        "<th>rotation RMSE [deg]</th><th>translation RMSE [mm]</th><th>evaluation [px]</th>"
                        "<th>MSM centre RMS [px]</th><th>observations</th><th>weak</th></tr>"]
    for c in calibrations:
        cells = [f"{c.get('registered', '-')}/{c.get('cameras', '-')}", _cell(c.get("rotation_rmse_deg"), "{:.4f}"),
                 _cell(c.get("translation_rmse_mm"), "{:.2f}"), _cell(c.get("eval_mean_px"), "{:.3f}"),
                 _cell(c.get("msm_centre_rms_px"), "{:.3f}"), str(c.get("observations", "-")),
                 html.escape(", ".join(c.get("weak", [])) or "-")]
        calibration_rows.append(f'<tr><td class="name">{html.escape(c["family"])}</td><td class="name">'
                                f'{html.escape(c["condition"])}</td>' + "".join(f"<td>{x}</td>" for x in cells)
                                + "</tr>")
    setting_text = html.escape(", ".join(f"{k} {v}" for k, v in settings.items()))
    return "\n".join([
        "<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        "<title>calibproj marker study</title>", f"<style>{STYLE}</style></head><body>",
        "<h1>Marker study</h1>",
        f'<p class="meta">calibproj {html.escape(__version__)}; {setting_text}</p>',
        "<h2>Recommendation</h2>", "<ul>" + "".join(f"<li>{html.escape(line)}</li>" for line in advice) + "</ul>",
        f'<div class="scroll"><table>{"".join(rows)}</table></div>',
        "<p>Images: one camera straight down at one projected array, rendered with known truth; a marker is "
        "found when detected with its id within 3 px of its true centre, a false detection otherwise.</p>",
        f'<div class="grid">{figures}</div>',
        "<h2>Calibrations</h2>", f'<div class="scroll"><table>{"".join(calibration_rows)}</table></div>',
        "</body></html>", ""])


def _cell(value: Any, pattern: str) -> str:
    return "-" if value is None or _nan(value) else pattern.format(value)


def write_recordings(out: Path, comparison: dict[str, Any]) -> Path:
    """``study.json`` and ``study.html`` of a comparison of recordings."""
    write_json(out / "study.json", STUDY_KIND, STUDY_MAJOR, _finite({"calibproj": __version__, **comparison}))
    runs = comparison["runs"]
    names = list(dict.fromkeys(n for run in runs for n in run["cameras"]))
    header = "<tr><th class=\"name\">camera</th>" + "".join(
        f"<th>{html.escape(str(run['markers']))}: MSMs (per scale) / centre spread per scale / fit residual [px]</th>"
        for run in runs) + "</tr>"
    rows = [header]
    for name in names:
        cells = []
        for run in runs:
            camera = run["cameras"].get(name)
            if camera is None or camera["status"] != "ok":
                cells.append("failed" if camera else "-")
                continue
            scales = ", ".join(f"{k}x {v}" for k, v in camera["kept_per_scale"].items())
            spread = ", ".join(f"{k}x {v:.3f}" for k, v in camera.get("centre_spread_px", {}).items()) or "-"
            residual = _cell(camera["fit_residual_px"], "{:.3f}")
            cells.append(f"{camera['msms_kept']} ({html.escape(scales)}) / {html.escape(spread)} / {residual}")
        rows.append(f'<tr><td class="name">{html.escape(name)}</td>'
                    + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    agreement = []
    for pair in comparison["agreement"]:
        per_camera = ", ".join(f"{html.escape(n)} {c['rotation_deg']:.4f} deg" + (
            f" / {c['translation_mm']:.1f} mm" if c.get("translation_mm") is not None else "")
            for n, c in pair["cameras"].items())
        centres = "" if pair["translation_rmse_mm"] is None else f", centres {pair['translation_rmse_mm']:.1f} mm"
        agreement.append(f"<li>{html.escape(pair['a'])} vs {html.escape(pair['b'])}: rotation RMSE "
                         f"{pair['rotation_rmse_deg']:.4f} deg{centres} ({per_camera})</li>")
    page = out / "study.html"
    atomic_write_text(page, "\n".join([
        "<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        "<title>calibproj marker study: recordings</title>", f"<style>{STYLE}</style></head><body>",
        "<h1>Marker study: your recordings</h1>",
        f'<div class="scroll"><table>{"".join(rows)}</table></div>',
        "<h2>Agreement of the calibrations (after Sim(3) alignment)</h2>", f"<ul>{''.join(agreement)}</ul>",
        "</body></html>", ""]))
    return page
