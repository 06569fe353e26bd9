"""The board calibration's plot: where the corners of the views used lie in the image
(distortion is measured only there) and each view's reprojection error."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from calibproj.board.calibration import BoardCalibration
from calibproj.report.figures import DEFAULT_DPI, png_bytes


def coverage_figure(result: BoardCalibration, dpi: int = DEFAULT_DPI) -> bytes:
    figure = Figure(figsize=(12.0, 4.5))
    coverage, errors = figure.subplots(1, 2, gridspec_kw={"width_ratios": [1.3, 1.0]})
    width, height = result.intrinsics.resolution
    for view in result.views:
        coverage.plot(*view.image_points.T, ".", markersize=2)
    coverage.set_xlim(-0.5, width - 0.5)
    coverage.set_ylim(height - 0.5, -0.5)
    coverage.set_aspect("equal")
    coverage.set_title(f"corners of the {len(result.views)} views used (a colour per view)", fontsize=10)
    coverage.set_xlabel("x [px]")
    coverage.set_ylabel("y [px]")
    positions = np.arange(len(result.views))
    errors.bar(positions, result.view_rms_px, color="#2b7bba")
    errors.axhline(result.rms_px, color="black", linewidth=1, label=f"all views {result.rms_px:.3f} px")
    errors.set_xticks(positions, [v.label for v in result.views], rotation=90, fontsize=6)
    errors.set_ylabel("RMS reprojection error [px]")
    K = result.intrinsics.K
    sigma = result.sigmas
    errors.set_title(f"fx {K[0, 0]:.1f} +- {sigma.get('fx', float('nan')):.1f} px, "
                     f"fy {K[1, 1]:.1f} +- {sigma.get('fy', float('nan')):.1f} px", fontsize=10)
    errors.legend(fontsize=8)
    figure.tight_layout()
    return png_bytes(figure, dpi)
