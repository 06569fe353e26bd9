"""The calibration report: one self-contained HTML page and its plots as PNG files.

``write_report(results_dir, tracks, intrinsics)`` reads a results folder (what
``calibproj calibrate`` writes; the tracks and intrinsics default to its tracks.json
and intrinsics/) and writes ``<results_dir>/report.html`` (no network:
every plot is embedded as a base64 PNG) and the same plots as ``<results_dir>/report/*.png``:

- ``scene_3d.png``: the cameras as frusta, the floor and the points, in 3D;
- ``scene_views.png``: the same seen from above and from the side;
- ``errors.png``: every camera's mean and standard deviation of reprojection error;
- ``camera_<name>.png`` per camera: the histogram of its reprojection errors, the
  residuals drawn over its image (arrows coloured by error), and how its observations
  cover the image.

The page adds a table per camera (mean and std error, observations, inliers,
observations of points seen by two cameras or more, view score) and shows a failed
camera with its reason in red. Plots are drawn with matplotlib's Agg canvas (headless).
"""

from calibproj.report.page import write_report

__all__ = ["write_report"]
