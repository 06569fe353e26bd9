"""The report's 3D view of the cameras, their frusta, the floor, the planes and the
points, turned and zoomed in the page: a plotly figure whose library is written into
the page itself, so that it works offline and the page stays one file."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from calibproj.formats.calibration import Calibration
from calibproj.report.data import CameraView
from calibproj.report.figures import (FRUSTUM_SHARE, camera_colours, drawable_views, floor_outline, frustum,
                                      plane_outlines, scene_extent, subsampled)


def _rgb(colour: Sequence[float]) -> str:
    return "rgb({},{},{})".format(*(int(round(255 * c)) for c in colour[:3]))


def _polygon(outline: np.ndarray, name: str, colour: str, opacity: float):
    """A flat polygon (its vertices in order, (N, 3)) as a fan of triangles."""
    import plotly.graph_objects as go

    n = len(outline)
    return go.Mesh3d(x=outline[:, 0], y=outline[:, 1], z=outline[:, 2], i=[0] * (n - 2), j=list(range(1, n - 1)),
                     k=list(range(2, n)), color=colour, opacity=opacity, name=name, hoverinfo="name")


def scene_figure(calibration: Calibration, views: Sequence[CameraView]):
    """The plotly figure: floor, planes, points, and per camera its frustum and name."""
    import plotly.graph_objects as go

    figure = go.Figure()
    _, extent = scene_extent(calibration)
    points = calibration.points
    if len(points) >= 3:
        on_floor = np.abs(points[:, 2]) < 0.01 * extent
        outline = floor_outline(points[on_floor] if on_floor.sum() >= 3 else points)
        figure.add_trace(_polygon(np.column_stack([outline, np.zeros(len(outline))]), "floor", "#bdbdbd", 0.35))
    for k, outline in enumerate(plane_outlines(calibration, extent)):
        if len(outline) >= 3:
            figure.add_trace(_polygon(outline, f"plane {k + 1}", "#6baed6", 0.5))
    shown = subsampled(points)
    if len(shown):
        figure.add_trace(go.Scatter3d(x=shown[:, 0], y=shown[:, 1], z=shown[:, 2], mode="markers", name="points",
                                      marker={"size": 1.5, "color": "#666666"}, hoverinfo="skip"))
    drawable = drawable_views(views)
    for view, colour in zip(drawable, camera_colours(len(drawable))):
        corners = frustum(view, FRUSTUM_SHARE * extent)
        path = corners[[0, 1, 2, 3, 4, 1, 0, 2, 0, 3, 0, 4]]
        figure.add_trace(go.Scatter3d(x=path[:, 0], y=path[:, 1], z=path[:, 2], mode="lines", name=view.name,
                                      line={"color": _rgb(colour), "width": 4}, hoverinfo="name"))
        figure.add_trace(go.Scatter3d(x=corners[:1, 0], y=corners[:1, 1], z=corners[:1, 2], mode="markers+text",
                                      text=[view.name], textposition="top center", showlegend=False,
                                      marker={"size": 4, "color": _rgb(colour)}, name=view.name, hoverinfo="name"))
    unit = "m" if calibration.unit == "m" else "unit"
    figure.update_layout(
        scene={"aspectmode": "data", "xaxis_title": f"x [{unit}]", "yaxis_title": f"y [{unit}]",
               "zaxis_title": f"z [{unit}]"},
        margin={"l": 0, "r": 0, "t": 10, "b": 0}, height=600, legend={"itemsizing": "constant"})
    return figure


def scene_view_html(calibration: Calibration, views: Sequence[CameraView]) -> str:
    """The view as a block of the page, with the plotting library inline (about 5 MB)."""
    import plotly.io

    return plotly.io.to_html(scene_figure(calibration, views), full_html=False, include_plotlyjs=True,
                             config={"displaylogo": False, "responsive": True}, default_width="100%")
