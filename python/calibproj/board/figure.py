"""The board calibration's plot: where the corners of the views used lie in the image
(distortion is measured only there) and each view's reprojection error."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from calibproj.board.fit import BoardCalibration
from calibproj.report.figures import DEFAULT_DPI, png_bytes


# View labels written under the bars at most (more would be too small to read).
MAX_VIEW_LABELS = 20


def coverage_figure(result: BoardCalibration, dpi: int = DEFAULT_DPI) -> bytes:
    figure = Figure(figsize=(13.0, 5.5))
    coverage, errors = figure.subplots(1, 2, gridspec_kw={"width_ratios": [1.3, 1.0]})
    width, height = result.intrinsics.resolution
    for view in result.views:
        coverage.plot(*view.image_points.T, "o", markersize=4, markeredgewidth=0)
    coverage.set_xlim(-0.5, width - 0.5)
    coverage.set_ylim(height - 0.5, -0.5)
    coverage.set_aspect("equal")
    coverage.set_title(f"corners of the {len(result.views)} views used (a colour per view)", fontsize=13)
    coverage.set_xlabel("x [px]", fontsize=12)
    coverage.set_ylabel("y [px]", fontsize=12)
    coverage.tick_params(labelsize=11)
    positions = np.arange(len(result.views))
    errors.bar(positions, result.view_rms_px, color="#2b7bba")
    errors.axhline(result.rms_px, color="black", linewidth=1, label=f"all views {result.rms_px:.3f} px")
    # Every label while they fit; else every k-th, large enough to read.
    every = max(1, int(np.ceil(len(result.views) / MAX_VIEW_LABELS)))
    errors.set_xticks(positions[::every], [v.label for v in result.views][::every], rotation=90, fontsize=10)
    errors.set_ylabel("RMS reprojection error [px]", fontsize=12)
    errors.tick_params(axis="y", labelsize=11)
    K = result.intrinsics.K
    sigma = result.sigmas
    errors.set_title(f"fx {K[0, 0]:.1f} +- {sigma.get('fx', float('nan')):.1f} px, "
                     f"fy {K[1, 1]:.1f} +- {sigma.get('fy', float('nan')):.1f} px", fontsize=13)
    errors.legend(fontsize=11)
    figure.tight_layout()
    return png_bytes(figure, dpi)
