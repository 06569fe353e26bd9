"""File names made from camera names, which may hold any character."""

from __future__ import annotations

import os
import re
from pathlib import Path


def safe_file_names(names: list[str], prefix: str = "", suffix: str = ".png") -> dict[str, str]:
    """``<prefix><name><suffix>`` per name, characters unsafe in file names (or URL
    fragments) replaced by ``_``, made unique without regard to case (``_2``, ``_3``,
    ...) so that case-insensitive file systems keep them apart."""
    out: dict[str, str] = {}
    taken: set[str] = set()
    for name in names:
        stem = prefix + (re.sub(r"[^A-Za-z0-9_.-]", "_", name).lstrip(".") or "camera")
        candidate, number = stem, 1
        while candidate.lower() in taken:
            number += 1
            candidate = f"{stem}_{number}"
        taken.add(candidate.lower())
        out[name] = candidate + suffix
    return out


def path_as_recorded(path: str | os.PathLike, folder: str | os.PathLike) -> str:
    """How a results folder records an input's path: relative to the folder when the
    input lies beside it (under the folder's parent), so that the record survives when
    both are moved or renamed together (the demo writes everything in a staging folder
    renamed at the end); absolute otherwise. The core's rule, which provenance.json
    follows in both tools."""
    from calibproj import _core

    return _core.formats.path_as_recorded(Path(path), Path(folder))
