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

import logging

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
from calibproj.version import __version__

logging.getLogger(__name__).addHandler(logging.NullHandler())

__all__ = [
    "Calibration",
    "IngestOptions",
    "RegistrationOptions",
    "Tracks",
    "__version__",
    "calibrate",
    "compare",
    "detect",
    "detect_markers",
    "evaluate",
    "generate",
    "simulate_tracks",
]
