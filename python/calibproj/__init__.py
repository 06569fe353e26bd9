"""calibproj: external calibration of camera networks from projected multi-scale markers."""

from __future__ import annotations

import logging

__version__ = "0.1.0"

logging.getLogger(__name__).addHandler(logging.NullHandler())

# The tracks-only simulation and the pose comparison; these names shadow the
# subpackage calibproj.simulate and the module calibproj.compare as attributes, so
# import their contents with "from calibproj.simulate.scene import ...".
from calibproj.compare import compare  # noqa: E402
from calibproj.simulate import simulate_tracks as simulate  # noqa: E402

# Marker detection in one image, and the projection sequence generator. The function
# generate shadows the subpackage calibproj.generate in the same way: import from it
# with "from calibproj.generate.sequence import Sequence".
from calibproj.generate import generate  # noqa: E402
from calibproj.markers import detect_markers  # noqa: E402

# Calibration from videos or tracks (calibproj.pipeline), its options and its result.
from calibproj.calibration import Calibration  # noqa: E402
from calibproj.pipeline import calibrate  # noqa: E402
from calibproj.registration import RegistrationOptions  # noqa: E402
from calibproj.tracks import Tracks  # noqa: E402

# Evaluation on independent data; like compare, the function shadows its module
# calibproj.evaluate as an attribute (import from it with "from calibproj.evaluate import ...").
from calibproj.evaluate import evaluate  # noqa: E402

# From camera videos to MSM tracks (synchronisation, frame picking, detection).
from calibproj.ingest import detect  # noqa: E402
from calibproj.ingest_options import IngestOptions  # noqa: E402

__all__ = ["__version__"]
__all__ += ["Calibration", "RegistrationOptions", "Tracks", "calibrate"]
__all__ += ["compare", "simulate"]
__all__ += ["evaluate"]
__all__ += ["detect_markers", "generate"]
__all__ += ["IngestOptions", "detect"]
