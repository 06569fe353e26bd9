"""Schema-versioned JSON files, written atomically.

Every calibproj file carries ``"schema": "calibproj.<kind>/<major>"``. Readers
check the kind and refuse a newer major version with a message naming the file.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

SCHEMA_PREFIX = "calibproj."


class FormatError(ValueError):
    """A file that is not what it claims to be, with the file named in the message."""


def schema_tag(kind: str, major: int) -> str:
    return f"{SCHEMA_PREFIX}{kind}/{major}"


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` so that readers see the old file or the whole new one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        # mkstemp creates 0600; give the file the permissions a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_name, 0o666 & ~umask)
        os.replace(tmp_name, path)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    atomic_write_bytes(path, text.encode("utf-8"))


def write_json(path: str | os.PathLike, kind: str, major: int, body: dict[str, Any]) -> None:
    """Write ``body`` with its schema tag first, atomically."""
    document = {"schema": schema_tag(kind, major), **body}
    atomic_write_text(path, json.dumps(document, indent=1, allow_nan=False) + "\n")


def read_json_object(path: str | os.PathLike) -> dict[str, Any]:
    """Read a JSON file whose top level is an object; FormatError naming the file."""
    path = Path(path)
    if not path.is_file():
        raise FormatError(f"{path}: no such file")
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise FormatError(f"{path}: not valid JSON ({error})") from None
    if not isinstance(document, dict):
        raise FormatError(f"{path}: expected a JSON object at the top level")
    return document


def read_json(path: str | os.PathLike, kind: str, major: int) -> dict[str, Any]:
    """Read a calibproj JSON file of the given kind, checking its schema tag."""
    document = read_json_object(path)
    check_schema(Path(path), document.get("schema"), kind, major)
    return document


def check_schema(path: str | os.PathLike, tag: Any, kind: str, major: int) -> None:
    expected = schema_tag(kind, major)
    if not isinstance(tag, str) or not tag.startswith(SCHEMA_PREFIX) or "/" not in tag:
        raise FormatError(f"{path}: not a calibproj {kind} file (schema {tag!r}, expected {expected!r})")
    found_kind, _, found_major = tag[len(SCHEMA_PREFIX):].partition("/")
    if found_kind != kind:
        raise FormatError(f"{path}: is a calibproj {found_kind} file, expected {kind} ({expected!r})")
    if not found_major.isdigit() or int(found_major) > major:
        raise FormatError(
            f"{path}: schema {tag!r} is newer than this calibproj reads ({expected!r}); upgrade calibproj"
        )
