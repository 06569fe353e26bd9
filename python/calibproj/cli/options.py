"""Command-line options generated from an options dataclass, so every knob of the API is
also a CLI flag with the same default and the documentation of its docstring."""

from __future__ import annotations

import argparse
import dataclasses
import re
from typing import Any


def attribute_docs(cls: type) -> dict[str, str]:
    """The ``Attributes:`` entries of a Google-style class docstring, by name."""
    doc = cls.__doc__ or ""
    section = doc.split("Attributes:", 1)[1] if "Attributes:" in doc else ""
    docs: dict[str, str] = {}
    name = None
    for line in section.splitlines():
        match = re.match(r"\s{4,8}(\w+):\s*(.*)", line)
        if match and (line.startswith(" " * 8) and not line.startswith(" " * 9)):
            name = match.group(1)
            docs[name] = match.group(2).strip()
        elif name and line.strip():
            docs[name] += " " + line.strip()
    return docs


def add_shared_argument(parser: Any, command: str, name: str, extra_help: str = "", **kwargs: Any) -> None:
    """A flag that ``calibproj-native COMMAND`` takes too: its metavar and help are the
    core's (``_core.formats.command_flag``), ``extra_help`` what only this tool adds;
    ``kwargs`` (required, action, default, type) are argparse's."""
    from calibproj import _core

    flag = _core.formats.command_flag(command, name)
    if not flag.metavar:
        kwargs.setdefault("action", "store_true")
    else:
        kwargs["metavar"] = flag.metavar
    parser.add_argument(name, help=flag.help + extra_help, **kwargs)


def add_refine_argument(parser: Any) -> None:
    """``--refine-intrinsics``, as ``calibproj-native`` takes it (the help is the core's)."""
    from calibproj import _core

    parser.add_argument("--refine-intrinsics", action="append", metavar="[CAMERA=]ENTRIES",
                        help=_core.selfcal.refine_intrinsics_help)


def add_dataclass_arguments(parser: argparse.ArgumentParser, cls: type, title: str,
                            exclude: tuple[str, ...] = ()) -> None:
    """One ``--field-name`` flag per field of the dataclass ``cls`` (but the fields
    ``exclude`` names, which the command adds as it adds its common options); its help
    is the field's ``metadata["help"]`` or else its entry in the class docstring, and a
    field with ``metadata["choices"]`` takes only those."""
    group = parser.add_argument_group(title)
    docs = attribute_docs(cls)
    for f in dataclasses.fields(cls):
        if f.name in exclude:
            continue
        default = f.default
        flag = "--" + f.name.replace("_", "-")
        help_text = f"{f.metadata.get('help') or docs.get(f.name, '')} (default: {default})".replace("%", "%%")
        if f.metadata.get("choices"):
            group.add_argument(flag, choices=f.metadata["choices"], default=default, help=help_text)
        elif isinstance(default, bool):
            group.add_argument(flag, action=argparse.BooleanOptionalAction, default=default, help=help_text)
        elif isinstance(default, tuple):
            item_type = type(default[0]) if default else str
            group.add_argument(flag, type=_comma_list(item_type), default=default, metavar="A,B,...", help=help_text)
        else:
            group.add_argument(flag, type=type(default), default=default, help=help_text)


def dataclass_from_args(cls: type, args: argparse.Namespace, exclude: tuple[str, ...] = ()) -> Any:
    """``cls`` from the flags ``add_dataclass_arguments`` added (the fields ``exclude``
    names keep their defaults)."""
    return cls(**{f.name: getattr(args, f.name) for f in dataclasses.fields(cls) if f.name not in exclude})


def dataclass_changed_from_args(cls: type, args: argparse.Namespace, exclude: tuple[str, ...] = ()) -> Any:
    """``dataclass_from_args``, or None when every field has its default (so that the
    API's own choice of defaults for the call applies)."""
    options = dataclass_from_args(cls, args, exclude)
    return None if options == cls() else options


def _comma_list(item_type: type):
    def parse(text: str) -> tuple:
        try:
            return tuple(item_type(part) for part in text.split(",") if part.strip())
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a comma-separated list of {item_type.__name__}, got {text!r}")

    return parse


def add_detector_option_argument(parser: Any, command: str) -> None:
    add_shared_argument(parser, command, "--detector-option", action="append", default=[])


def parse_detector_options(items: list[str]) -> dict[str, Any]:
    """--detector-option NAME=VALUE values: name -> value (a Python literal, else the text)."""
    import ast

    options = {}
    for item in items:
        name, separator, text = item.partition("=")
        if not separator or not name:
            raise ValueError(f"--detector-option expects NAME=VALUE, got {item!r}")
        try:
            options[name.strip()] = ast.literal_eval(text.strip())
        except (ValueError, SyntaxError):
            options[name.strip()] = text.strip()
    return options


def add_exposure_argument(parser: Any, command: str, extra_help: str = "") -> None:
    add_shared_argument(parser, command, "--exposure", extra_help, action="append", default=[])


def parse_exposures(items: list[str]) -> dict[str, float]:
    """--exposure CAMERA=SECONDS values: camera name -> seconds."""
    from calibproj import _core

    exposures = {}
    for item in items:
        name, separator, text = item.partition("=")
        try:
            seconds = float(text)
        except ValueError:
            seconds = -1.0
        if not separator or not name or not _core.ingest.valid_known_exposure(seconds):
            raise ValueError(f"--exposure expects CAMERA=SECONDS with 0 < SECONDS <= 1, got {item!r}")
        exposures[name.strip()] = seconds
    return exposures
