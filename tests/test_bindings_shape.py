"""The bindings stay thin: they convert the core's types, they do not read Python
objects by attribute name nor hand data back as dictionaries (README, "calibproj-native").

Read from the binding sources: every ``attr("...")`` sets a module constant, and the only
functions returning a dictionary build the keyed collections of a typed class (a
calibration's poses, failures and metrics by camera; a lens's entries by name).
"""

from __future__ import annotations

import re
from pathlib import Path

BINDINGS = Path(__file__).resolve().parents[1] / "cpp" / "bindings"
# Keyed collections of typed classes: camera -> (R, t), camera -> reason,
# camera -> CameraMetrics, lens entry -> value.
DICTIONARY_FUNCTIONS = {"PosesOf", "FailedOf", "MetricsOf", "LensDict"}


def binding_sources() -> dict[str, str]:
    files = sorted([*BINDINGS.glob("*.cc"), *BINDINGS.glob("*.h")])
    assert len(files) > 10
    return {path.name: path.read_text(encoding="utf-8") for path in files}


def test_no_binding_reads_a_python_attribute_by_name() -> None:
    constant = re.compile(r'^\s*m\.attr\("\w+"\) = ')
    lookups = [f"{name}: {line.strip()}" for name, text in binding_sources().items()
               for line in text.splitlines() if 'attr("' in line and not constant.match(line)]
    assert not lookups, "attribute lookups in the bindings:\n" + "\n".join(lookups)


def test_no_binding_function_returns_a_dictionary_of_data() -> None:
    returning = re.compile(r"^(?:inline\s+)?(?:py|pybind11)::dict\s+(\w+)\(", re.MULTILINE)
    found = {match for text in binding_sources().values() for match in returning.findall(text)}
    assert found <= DICTIONARY_FUNCTIONS, f"dictionaries returned by {sorted(found - DICTIONARY_FUNCTIONS)}"
    assert found, "the pattern no longer finds the keyed collections: is it still right?"
