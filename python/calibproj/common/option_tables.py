"""Options classes made from the C++ core's option tables.

Each knob of the registration and of the ingest is declared once, in C++, with its
default and its help (``cpp/calibproj/registration/option_table.h``,
``cpp/calibproj/ingest/option_table.h``); both command lines walk those tables, and
the Python dataclasses here are made from them, so no side can miss, rename or
redefine a knob.
"""

from __future__ import annotations

import dataclasses
import textwrap
from collections.abc import Callable
from typing import Any


def options_class(name: str, table: list[Any], summary: str, module: str, *,
                  frozen: bool = False, methods: dict[str, Callable] | None = None) -> type:
    """A dataclass with one field per knob of ``table`` (``_core.Knob``: name, default,
    help, choices), in its order: the entry's default, its help as ``metadata["help"]``,
    its choices (if any) as ``metadata["choices"]``; documented by ``summary`` and an
    ``Attributes:`` section of the helps."""
    fields = []
    doc = [summary, "", "Attributes:"]
    for knob in table:
        metadata = {"help": knob.help, "choices": knob.choices}
        fields.append((knob.name, type(knob.default), dataclasses.field(default=knob.default, metadata=metadata)))
        doc.append(textwrap.fill(f"{knob.name}: {knob.help}", 88, initial_indent="    ",
                                 subsequent_indent="        "))
    cls = dataclasses.make_dataclass(name, fields, frozen=frozen,
                                     namespace={**(methods or {}), "__module__": module})
    cls.__doc__ = "\n".join(doc)
    return cls
