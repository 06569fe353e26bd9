"""The summary a command prints last, the one a person reads first: each camera's status
(the reference, ok, WEAK with its sigma and what helps, FAILED with why), its
uncertainty in the units of the report, and where the results and the report are."""

from __future__ import annotations

from pathlib import Path
from typing import Any

REFERENCE = "reference"
WEAK = "WEAK"
FAILED = "FAILED"


def camera_status(calibration: Any, name: str) -> str:
    """``Calibration.status``, a problem in capitals: ``reference``, ``ok``, ``WEAK``, ``FAILED``."""
    status = calibration.status(name)
    return status.upper() if status in ("weak", "failed") else status


def centre_unit(calibration: Any) -> tuple[str, float]:
    """The unit centre sigmas are given in, and the factor from the calibration's unit:
    millimetres in a metric calibration (as the report), else the calibration's unit."""
    return ("mm", 1e3) if calibration.unit == "m" else ("units", 1.0)


def format_cameras(calibration: Any, results: str | Path | None = None) -> str:
    """The camera table; under a weak camera, what its sigma is and what helps
    (``results``: the folder to name in the densify command)."""
    unit, factor = centre_unit(calibration)
    header = (f"{'camera':<14}{'status':<11}{'rotation sigma':>16}{'centre sigma':>16}"
              f"{'mean px':>9}{'points':>8}")
    lines = [header, "-" * len(header)]
    for name in sorted(set(calibration.metrics) | set(calibration.poses) | set(calibration.failed)):
        status = camera_status(calibration, name)
        metrics = calibration.metrics.get(name)
        if status == FAILED:
            reason = calibration.failed.get(name) or (metrics.failure if metrics is not None else None)
            lines.append(f"{name:<14}{status:<11}{reason or 'not registered'}")
            continue
        rotation = centre = "-"
        if status != REFERENCE and metrics is not None:
            if metrics.rotation_sigma_deg is not None:
                rotation = f"{metrics.rotation_sigma_deg:.4f} deg"
            if metrics.centre_sigma is not None:
                centre = f"{metrics.centre_sigma * factor:.3g} {unit}"
        mean = f"{metrics.mean_px:.3f}" if metrics is not None and metrics.mean_px is not None else "-"
        points = str(metrics.inliers) if metrics is not None else "-"
        lines.append(f"{name:<14}{status:<11}{rotation:>16}{centre:>16}{mean:>9}{points:>8}")
        if status == WEAK:
            lines.append(f"{'':<14}{_weak_advice(metrics, results)}")
    lines.append(f"sigmas: 1 sigma, relative to the reference camera; centre sigmas in {unit}")
    return "\n".join(lines)


def _weak_advice(metrics: Any, results: str | Path | None) -> str:
    folder = results if results is not None else "RESULTS"
    sigma = metrics.rotation_sigma_deg
    known = "pose poorly known" if sigma is None else f"rotation known to {sigma:.3f} deg only"
    return f"{known} (few points); more help: calibproj generate --densify {folder} --out DENSE"


def expected_error(results: str | Path, unit: str) -> str | None:
    """The expected 3D error of the results' uncertainty.json in one line, or None when
    there is none (or it cannot be read: the report says more)."""
    import json

    from calibproj.formats.results import UNCERTAINTY_FILE

    try:
        document = json.loads((Path(results) / UNCERTAINTY_FILE).read_text(encoding="utf-8"))
        centre, median = float(document["centre"]["sigma"]), float(document["volume"]["median_sigma"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    length = (lambda v: f"{1000.0 * v:.1f} mm") if unit == "m" else (lambda v: f"{v:.3g} units")
    return (f"expected 3D error (1 sigma): {length(centre)} at the table above the projection's centre, "
            f"{length(median)} median over the working volume")


def unit_words(calibration: Any) -> str:
    if calibration.unit == "m":
        return "in metres"
    return "unit: the reference camera's height above the floor; --scale gives metres"
