"""Schema-versioned JSON files, written atomically and read strictly.

Every calibproj file carries ``"schema": "calibproj.<kind>/<major>"``. Readers
check the kind and refuse a newer major version with a message naming the file.

Reading takes JSON as calibproj-native does: no ``NaN`` or ``Infinity`` (not JSON), no
number beyond a double's range (``1e400``), no arrays and objects nested deeper than
``MAX_DEPTH``. The values' types are checked by each format's reader
(``calibproj.formats.json_values``).
"""

from __future__ import annotations

import errno
import json
import math
import os
import re
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from calibproj import _core

SCHEMA_PREFIX = "calibproj."
# Arrays and objects nested deeper than this are refused, as by calibproj-native
# (cpp/app/files.h, kMaxJsonDepth): no calibproj file comes near.
MAX_DEPTH = 512
# Integers of more digits are read as doubles, as calibproj-native's parser does with
# an integer beyond 64 bits (so 1 followed by 400 zeros is out of range, like 1e400).
MAX_INTEGER_DIGITS = 20
_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"')
_NOT_BRACKETS = bytes(sorted(set(range(256)) - set(b"[]{}")))


# A file that is not what it claims to be, with the file named in the message: the
# core's error, so that one except clause takes what either language's readers raise.
FormatError = _core.formats.InputError


def schema_tag(kind: str, major: int) -> str:
    return f"{SCHEMA_PREFIX}{kind}/{major}"


def require_replaceable(path: str | os.PathLike) -> None:
    """FileExistsError naming ``path`` when something other than a regular file is there:
    a file written whole replaces what is at its path, and a device, a pipe or a folder
    must not be (as root, "/dev/null" would become a plain file)."""
    path = Path(path)
    if path.exists() and not path.is_file():
        raise FileExistsError(errno.EEXIST, "not a regular file; nothing written over it", str(path))


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` so that readers see the old file or the whole new one."""
    path = Path(path)
    require_replaceable(path)
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
    """Write ``body`` with its schema tag first, atomically; ValueError naming the file
    for a value JSON cannot hold (NaN, infinity), with nothing written."""
    document = {"schema": schema_tag(kind, major), **body}
    try:
        text = json.dumps(document, indent=1, allow_nan=False)
    except ValueError:
        raise ValueError(f"{path}: cannot write the {kind} file: a value is NaN or infinite, which JSON "
                         f"cannot hold") from None
    atomic_write_text(path, text + "\n")


def read_json_value(path: str | os.PathLike) -> Any:
    """Read any JSON file strictly (see the module docstring); FormatError naming the file."""
    from calibproj import _core

    path = Path(path)
    if not path.is_file():
        raise FormatError(f"{path}: no such file")
    container = _core.formats.video_container(path)
    if container:
        raise FormatError(f"{path}: is a video ({container}), not a JSON file")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as error:
        raise FormatError(f"{path}: not valid JSON (not UTF-8: {error})") from None
    return parse_json(text, str(path))


def parse_json(text: str, source: str) -> Any:
    """The JSON value of ``text``, strictly; FormatError naming ``source``."""
    too_deep = f"{source}: not valid JSON (arrays and objects nested deeper than {MAX_DEPTH} levels)"
    try:
        document = json.loads(text, parse_constant=_refuse_constant, parse_float=_finite_float,
                              parse_int=_integer_or_double)
    except json.JSONDecodeError as error:
        raise FormatError(f"{source}: not valid JSON ({error})") from None
    except RecursionError:  # nesting deeper than the interpreter's stack
        raise FormatError(too_deep) from None
    except ValueError as error:  # the hooks' refusals
        raise FormatError(f"{source}: not valid JSON ({error})") from None
    if nesting_depth(text) > MAX_DEPTH:
        raise FormatError(too_deep)
    return document


def nesting_depth(text: str) -> int:
    """How deep the arrays and objects of valid JSON text nest (0 for a number)."""
    without_strings = _JSON_STRING.sub("", text).encode("utf-8")
    brackets = np.frombuffer(without_strings.translate(None, _NOT_BRACKETS), dtype=np.uint8)
    if brackets.size == 0:
        return 0
    opening = (brackets == ord("[")) | (brackets == ord("{"))
    return int(np.cumsum(np.where(opening, 1, -1)).max())


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"number {_shortened(text)} is beyond the range of a double")
    return value


def _integer_or_double(text: str) -> int | float:
    digits = len(text.lstrip("-"))
    return int(text) if digits <= MAX_INTEGER_DIGITS else _finite_float(text)


def _shortened(text: str, limit: int = 40) -> str:
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def read_json_object(path: str | os.PathLike) -> dict[str, Any]:
    """Read a JSON file whose top level is an object; FormatError naming the file."""
    path = Path(path)
    document = read_json_value(path)
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
