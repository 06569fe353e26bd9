"""The package version, from one source: the ``version`` of ``pyproject.toml``.

An installed calibproj reads it from its distribution metadata (written from
pyproject.toml when the package is built); a source checkout imported without being
installed reads pyproject.toml itself.
"""

from __future__ import annotations

import re
from importlib import metadata
from pathlib import Path

DISTRIBUTION = "calibproj"
PYPROJECT = Path(__file__).resolve().parents[2] / "pyproject.toml"
UNKNOWN = "0+unknown"


def package_version() -> str:
    """The version of the installed distribution, else that of the source checkout."""
    try:
        return metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        return pyproject_version(PYPROJECT)


def pyproject_version(path: Path) -> str:
    """``[project] version`` of a pyproject.toml; ``0+unknown`` when there is none."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError:
        return UNKNOWN
    # The [project] table up to the next table header (tomllib is not in Python 3.10).
    table = re.search(r"^\[project\]\s*$(.*?)(?=^\[|\Z)", text, re.MULTILINE | re.DOTALL)
    version = re.search(r"^version\s*=\s*[\"']([^\"']+)[\"']", table.group(1), re.MULTILINE) if table else None
    return version.group(1) if version else UNKNOWN


__version__ = package_version()
