"""The marker study on a user's own recordings: the same room calibrated twice, once
with each family's sequence (two results folders of ``calibproj calibrate``), compared
camera by camera: markers kept per scale, how far each scale's centres lie from their
MSM's merged centre (the centres' repeatability), fit residuals, and how far the two
calibrations agree after Sim(3) alignment."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from calibproj.formats.results import DETECT_REPORT_FILE


def compare_recordings(folders: list[Path]) -> dict[str, Any]:
    """Per results folder its family and cameras; per pair of folders the agreement of
    their poses. ValueError naming a folder that is not a calibration from videos."""
    from calibproj.formats.calibration import Calibration
    from calibproj.evaluation.comparison import compare

    runs = []
    for folder in folders:
        report_path = folder / DETECT_REPORT_FILE
        if not report_path.is_file():
            raise ValueError(f"{folder}: no {DETECT_REPORT_FILE} (a results folder of calibproj calibrate "
                             "from videos is needed)")
        try:
            report = json.loads(report_path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as error:
            raise ValueError(f"{report_path}: not readable ({error})") from None
        calibration = Calibration.load(folder)
        cameras = {}
        for name, camera in (report.get("cameras") or {}).items():
            metrics = calibration.metrics.get(name)
            cameras[name] = {
                "status": camera.get("status"),
                "msms_kept": camera.get("msms_kept"),
                "kept_per_scale": {str(s.get("scale")): s.get("kept") for s in camera.get("scales", [])},
                # Repeatability: RMS distance of a scale's centres from their MSM's merged centre.
                "centre_spread_px": {str(s.get("scale")): s.get("spread_px") for s in camera.get("scales", [])
                                     if s.get("spread_px") is not None},
                "fit_residual_px": None if metrics is None else metrics.mean_px,
                "registered": name in calibration.poses,
            }
        runs.append({"folder": str(folder), "markers": report.get("markers"), "cameras": cameras})
    agreement = []
    for i, first in enumerate(folders):
        for second in folders[i + 1:]:
            result = compare(first / "camera_poses.json", second / "camera_poses.json")
            agreement.append({"a": str(first), "b": str(second), "rotation_rmse_deg": result.rotation_rmse_deg,
                              "translation_rmse_mm": result.translation_rmse_mm,
                              "cameras": {n: {"rotation_deg": c.rotation_deg, "translation_mm": c.translation_mm}
                                          for n, c in result.cameras.items()}})
    return {"runs": runs, "agreement": agreement}
