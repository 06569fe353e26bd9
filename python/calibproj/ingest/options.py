"""Options of the video ingest (``calibproj.detect``), with their defaults.

Every knob is declared once, with its default and help, in the C++ ingest's table
(``cpp/calibproj/ingest/option_table.h``); ``IngestOptions`` is made from it, as both
tools' command lines are.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from calibproj import _core
from calibproj.common.option_tables import options_class


def _replace(self, **changes: Any) -> Any:
    """A copy with some fields changed; ValueError naming an unknown field."""
    known = {f.name for f in dataclasses.fields(self)}
    unknown = sorted(set(changes) - known)
    if unknown:
        raise ValueError(f"unknown ingest option(s) {', '.join(unknown)} (choose from {', '.join(sorted(known))})")
    return dataclasses.replace(self, **changes)


def _to_kwargs(self) -> dict[str, Any]:
    """Keyword arguments of ``calibproj._core.ingest.ingest_camera``."""
    return dataclasses.asdict(self)


# Every ingest knob, declared once in the C++ core (``_core.ingest.option_table``).
IngestOptions = options_class(
    "IngestOptions", _core.ingest.option_table(),
    """Knobs of synchronisation, frame picking, detection and merging.

Synchronisation finds the start and end light codes in the per-frame mean luma
(``cpp/calibproj/sync``); frames are picked from the resulting frame map; markers
are detected in regions of interest predicted by the projector-to-image homography
once the first detections give it; the scales of each MSM are merged.""",
    __name__, frozen=True, methods={"replace": _replace, "to_kwargs": _to_kwargs})


def sync_kwargs(options: IngestOptions, camera_fps: float) -> dict[str, Any]:
    """The synchronisation part of the options (``calibproj._core.sync`` keywords), the
    exposure in the camera's frames."""
    names = {knob.name for knob in _core.sync.option_table()}
    kwargs = {name: value for name, value in options.to_kwargs().items() if name in names}
    kwargs["fixed_exposure"] = options.exposure_s * camera_fps
    return kwargs
