"""Typed values of the JSON documents calibproj reads, checked as calibproj-native does.

A number is a JSON number: ``true`` and ``false`` are not (Python's ``bool`` is an
``int``), nor is a string of digits. An integer is a number without a fractional part
(``3`` or ``3.0``). The readers of ``calibproj.formats.jsonio`` already refuse NaN,
infinities and numbers beyond a double's range; the arrays here are checked finite
anyway, for documents that come from elsewhere.

Every check raises ``ValueError`` naming the entry (``where``, e.g.
``observations.cam0.xy``); each format's reader adds the file.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

NUMBER_TYPES = (int, float)
# Values longer than this are shortened in messages (a message is one line to read).
DESCRIBE_CHARACTERS = 40


def describe(value: Any) -> str:
    """A short description of a value for a message: as JSON writes it (``true``,
    ``null``, ``"text"``), or its kind and beginning when long."""
    names = {str: "a string", list: "a list", dict: "an object"}
    try:
        written = json.dumps(value)
    except (TypeError, ValueError):  # not a JSON value (a caller's numpy array, ...)
        written = repr(value)
    if len(written) <= DESCRIBE_CHARACTERS:
        return written
    length = f" of {len(value)} items" if isinstance(value, (list, dict)) else ""
    return f"{names.get(type(value), type(value).__name__)}{length} ({written[:DESCRIBE_CHARACTERS]}...)"


def is_number(value: Any) -> bool:
    """A JSON number: an int or a float, not a bool."""
    return type(value) in NUMBER_TYPES


def number(value: Any, where: str, minimum: float | None = None, maximum: float | None = None) -> float:
    """A finite number in ``[minimum, maximum]`` (either bound may be None)."""
    if not is_number(value) or not math.isfinite(value):
        raise ValueError(f"{where}: expected a finite number, got {describe(value)}")
    _check_range(value, where, minimum, maximum)
    return float(value)


def integer(value: Any, where: str, minimum: int | None = None, maximum: int | None = None) -> int:
    """An integer (``3`` or ``3.0``) in ``[minimum, maximum]`` (either bound may be None)."""
    if not is_number(value) or not math.isfinite(value) or value != math.floor(value):
        raise ValueError(f"{where}: expected an integer, got {describe(value)}")
    _check_range(value, where, minimum, maximum)
    return int(value)


def boolean(value: Any, where: str) -> bool:
    if type(value) is not bool:
        raise ValueError(f"{where}: expected true or false, got {describe(value)}")
    return value


def text(value: Any, where: str) -> str:
    if type(value) is not str:
        raise ValueError(f"{where}: expected a string, got {describe(value)}")
    return value


def number_array(value: Any, where: str, shape: tuple[int | None, ...] | None = None) -> np.ndarray:
    """Nested lists of numbers (rows of equal length) as a float array; with ``shape``,
    of that shape (None: any length). A numeric numpy array is taken as it is."""
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "iuf":
            raise ValueError(f"{where}: expected numbers, got an array of {value.dtype}")
        array = value.astype(float)
    else:
        flat, dims = _flatten(value, where)
        _check_numbers(flat, where)
        try:
            array = np.array(flat, dtype=float).reshape(dims)
        except OverflowError:  # an int beyond a double's range, from a document not read from JSON
            raise ValueError(f"{where}: a number beyond the range of a double") from None
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{where}: numbers must be finite")
    if shape is not None:
        array = _with_shape(array, where, shape)
    return array


def _check_range(value: float, where: str, minimum: float | None, maximum: float | None) -> None:
    if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
        if maximum is None:
            bounds = f"at least {_bound(minimum)}"
        elif minimum is None:
            bounds = f"at most {_bound(maximum)}"
        else:
            bounds = f"in [{_bound(minimum)}, {_bound(maximum)}]"
        raise ValueError(f"{where}: must be {bounds}, got {describe(value)}")


def _bound(value: float) -> str:
    return str(value) if isinstance(value, int) else f"{value:g}"


def _flatten(value: Any, where: str) -> tuple[list, tuple[int, ...]]:
    """The leaves of nested lists, and the lists' shape; ValueError when rows differ."""
    if type(value) is not list:
        return [value], ()
    dims, level = [], [value]
    while level and all(type(item) is list for item in level):
        lengths = set(map(len, level))
        if len(lengths) > 1:
            raise ValueError(f"{where}: rows of different lengths ({', '.join(map(str, sorted(lengths)[:4]))})")
        dims.append(lengths.pop())
        level = [leaf for item in level for leaf in item]
    if any(type(item) is list for item in level):
        raise ValueError(f"{where}: numbers and lists mixed at one level")
    return level, tuple(dims)


def _check_numbers(flat: list, where: str) -> None:
    if not set(map(type, flat)) <= set(NUMBER_TYPES):
        bad = next(item for item in flat if not is_number(item))
        raise ValueError(f"{where}: expected numbers, got {describe(bad)}")


def _with_shape(array: np.ndarray, where: str, shape: tuple[int | None, ...]) -> np.ndarray:
    if array.shape == (0,) and shape[0] is None:  # an empty list: no rows
        return np.zeros((0, *(n or 0 for n in shape[1:])))
    fits = array.ndim == len(shape) and all(n is None or n == d for n, d in zip(shape, array.shape))
    if not fits:
        expected = "x".join("N" if n is None else str(n) for n in shape)
        found = "x".join(map(str, array.shape)) or "a single number"
        raise ValueError(f"{where}: expected {expected} numbers, got {found}")
    return array
