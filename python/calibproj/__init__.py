"""calibproj: external calibration of camera networks from projected multi-scale markers.

The workflow as functions: ``generate`` (the projection sequence), ``detect`` (camera
videos to MSM tracks), ``calibrate`` (videos or tracks to a calibration and its results
folder), ``compare`` (poses against a reference) and ``evaluate`` (on independent
data); ``detect_markers`` finds markers in one image. Simulated camera networks live
in the subpackage ``calibproj.simulate`` (``simulate_tracks`` is also exported here).
``triangulation_uncertainty`` tells how accurately the calibrated cameras place given
points.

The package is laid out by stage, as the C++ core it drives: ``common``, ``formats``,
``sequence``, ``simulate``, ``ingest``, ``selfcal``, ``scale``, ``registration``,
``uncertainty``, ``evaluation``, ``report``, ``board``, then ``pipeline`` (the whole
calibration), ``check``, ``capture``, ``study`` and ``cli``; a stage imports only the
stages before it. Every module is importable by its dotted name: no name exported here
is also the name of a submodule (the projection sequence lives in ``calibproj.sequence``,
the pose comparison in ``calibproj.evaluation.comparison``).
"""

# No "from __future__ import ..." and no call at the top level: importing __future__
# runs the import machinery in this module's frame, and a Ctrl-C at the very start
# (before the command line's handler exists) would be reported from here.
import importlib

TYPE_CHECKING = False  # typing.TYPE_CHECKING without importing typing at start

if TYPE_CHECKING:
    from calibproj.version import __version__
    from calibproj.formats.calibration import Calibration
    from calibproj.evaluation.comparison import compare
    from calibproj.evaluation.independent import evaluate
    from calibproj.ingest.videos import detect
    from calibproj.ingest.options import IngestOptions
    from calibproj.sequence.markers import detect_markers
    from calibproj.pipeline import calibrate
    from calibproj.registration.driver import RegistrationOptions
    from calibproj.sequence import generate
    from calibproj.simulate import simulate_tracks
    from calibproj.formats.tracks import Tracks
    from calibproj.uncertainty.triangulation import triangulation_uncertainty

# Each exported name and the module that defines it, imported on first use: the
# command line starts without numpy, OpenCV, the C++ core (or even logging) loaded, so
# that Ctrl-C at its start meets its own handler.
_EXPORTS = {
    "__version__": "calibproj.version",
    "Calibration": "calibproj.formats.calibration",
    "IngestOptions": "calibproj.ingest.options",
    "RegistrationOptions": "calibproj.registration.driver",
    "Tracks": "calibproj.formats.tracks",
    "calibrate": "calibproj.pipeline",
    "compare": "calibproj.evaluation.comparison",
    "detect": "calibproj.ingest.videos",
    "detect_markers": "calibproj.sequence.markers",
    "evaluate": "calibproj.evaluation.independent",
    "generate": "calibproj.sequence",
    "simulate_tracks": "calibproj.simulate",
    "triangulation_uncertainty": "calibproj.uncertainty.triangulation",
}

__all__ = [*_EXPORTS]


def __getattr__(name: str) -> object:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'calibproj' has no attribute {name!r}")
    import logging

    # The library's log is the application's to show (the command line configures it).
    logger = logging.getLogger(__name__)
    if not any(isinstance(handler, logging.NullHandler) for handler in logger.handlers):
        logger.addHandler(logging.NullHandler())
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})
