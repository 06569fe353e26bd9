"""calibproj: external calibration of camera networks from projected multi-scale markers.

The workflow as functions: ``generate`` (the projection sequence), ``detect`` (camera
videos to MSM tracks), ``calibrate`` (videos or tracks to a calibration and its results
folder), ``compare`` (poses against a reference) and ``evaluate`` (on independent
data); ``detect_markers`` finds markers in one image. Simulated camera networks live
in the subpackage ``calibproj.simulate`` (``simulate_tracks`` is also exported here).

Every module is importable by its dotted name: no name exported here is also the name
of a submodule (the projection sequence lives in ``calibproj.sequence``, the pose
comparison in ``calibproj.comparison``, the evaluation in ``calibproj.evaluation``).
"""

from __future__ import annotations

import importlib
import logging
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from calibproj.version import __version__
    from calibproj.calibration import Calibration
    from calibproj.comparison import compare
    from calibproj.evaluation import evaluate
    from calibproj.ingest import detect
    from calibproj.ingest_options import IngestOptions
    from calibproj.markers import detect_markers
    from calibproj.pipeline import calibrate
    from calibproj.registration import RegistrationOptions
    from calibproj.sequence import generate
    from calibproj.simulate import simulate_tracks
    from calibproj.tracks import Tracks

# Each exported name and the module that defines it, imported on first use: the
# command line starts without numpy, OpenCV and the C++ core loaded, so that Ctrl-C at
# its start meets its own handler.
_EXPORTS = {
    "__version__": "calibproj.version",
    "Calibration": "calibproj.calibration",
    "IngestOptions": "calibproj.ingest_options",
    "RegistrationOptions": "calibproj.registration",
    "Tracks": "calibproj.tracks",
    "calibrate": "calibproj.pipeline",
    "compare": "calibproj.comparison",
    "detect": "calibproj.ingest",
    "detect_markers": "calibproj.markers",
    "evaluate": "calibproj.evaluation",
    "generate": "calibproj.sequence",
    "simulate_tracks": "calibproj.simulate",
}

logging.getLogger(__name__).addHandler(logging.NullHandler())

__all__ = list(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'calibproj' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})
