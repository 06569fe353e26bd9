"""The result of a calibration: camera poses in the floor frame, points, per-camera metrics.

``Calibration`` is the core's type (``_core.formats.Calibration``), the one that
``calibproj-native`` holds too; its files (``save``/``load``) are ``camera_poses.json``,
``metrics.json`` and ``points.ply``. Floor frame (docs/conventions.md): z up, floor z = 0;
origin at the floor projection of the centroid of the registered camera centres; x along
the floor projection of the first registered camera's optical axis. Without a metric
measurement the unit is arbitrary and the first registered camera is at height 1.
"""

from __future__ import annotations

from calibproj._core.formats import Calibration, CameraMetrics, CameraPose, Plane

__all__ = ["Calibration", "CameraMetrics", "CameraPose", "Plane"]
