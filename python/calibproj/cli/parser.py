"""The argument parser of the command line: argparse with "did you mean" hints.

A mistyped subcommand or option is reported as argparse reports it, followed by the
closest known name (``difflib``; argparse itself suggests only from Python 3.14):

    calibproj: error: argument COMMAND: invalid choice: 'calbrate' (choose from ...) (did you mean 'calibrate'?)
    calibproj calibrate: error: unrecognized arguments: --forse (did you mean --force?)

Subparsers made by ``add_subparsers().add_parser`` are of the same class.
"""

from __future__ import annotations

import argparse
import difflib
import re
import sys
from collections.abc import Iterable, Mapping, Sequence
from typing import NoReturn

# How close a known name must be to be suggested (difflib ratio).
SUGGESTION_CUTOFF = 0.6
NEGATIVE_NUMBER = re.compile(r"^-\d+$|^-\d*\.\d+$")


def closest(word: str, candidates: Iterable[str]) -> str | None:
    """The candidate closest to ``word``, if one is close enough."""
    matches = difflib.get_close_matches(word, sorted(set(candidates)), n=1, cutoff=SUGGESTION_CUTOFF)
    return matches[0] if matches else None


class SuggestingArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose errors suggest the subcommand or option meant."""

    arguments: Sequence[str] = ()  # the arguments of the last parse
    # A subcommand's parser: every subcommand by name (set by the program that makes them),
    # so that an option of another subcommand is named as such.
    siblings: Mapping[str, argparse.ArgumentParser] | None = None

    def parse_known_args(self, args=None, namespace=None):
        self.arguments = list(sys.argv[1:] if args is None else args)
        return super().parse_known_args(args, namespace)

    def error(self, message: str) -> NoReturn:
        super().error(message + self._hint(message))

    # -- suggestions --------------------------------------------------------------------------

    def _hint(self, message: str) -> str:
        choice = re.search(r"argument (\S+): invalid choice: '([^']*)'", message)
        if choice:
            suggestion = closest(choice.group(2), self._choices_of(choice.group(1)))
            return f" (did you mean {suggestion!r}?)" if suggestion else ""
        candidates = self._option_candidates()
        hints = []
        for option in self._unknown_options():
            elsewhere = self._commands_with(option)
            suggestion = closest(option, candidates)
            if elsewhere:  # an exact name of another command beats a look-alike of this one
                hints.append(f"{option} is an option of calibproj {' and '.join(elsewhere)}")
            elif suggestion:
                hints.append(f"did you mean {suggestion}?" if option in message
                             else f"{option}: did you mean {suggestion}?")
        return f" ({'; '.join(hints)})" if hints else ""

    def _commands_with(self, option: str) -> list[str]:
        """The subcommands (this parser's, or its siblings) that take ``option``."""
        commands = dict(self.siblings or {})
        for action in self._actions:
            if isinstance(action.choices, Mapping):
                commands.update(action.choices)
        return [name for name, sub in commands.items() if sub is not self
                and any(option in a.option_strings for a in sub._actions)]

    def _choices_of(self, name: str) -> list[str]:
        """The choices of the argument argparse names ``name`` in its message."""
        for action in self._actions:
            names = {"/".join(action.option_strings), action.metavar, action.dest}
            if action.choices is not None and name in names:
                return [str(choice) for choice in action.choices]
        return []

    def _option_candidates(self) -> list[str]:
        """Option strings of this parser and of the subcommand named in its arguments."""
        options = [s for action in self._actions for s in action.option_strings]
        for action in self._actions:
            if isinstance(action.choices, Mapping):  # the subcommands
                chosen = next((a for a in self.arguments if a in action.choices), None)
                if chosen is not None:
                    options += [s for sub in action.choices[chosen]._actions for s in sub.option_strings]
        return options

    def _unknown_options(self) -> list[str]:
        """The options in the arguments that no known option is, nor abbreviates."""
        known = self._option_candidates()
        unknown = []
        for argument in self.arguments:
            if argument == "--":
                break
            if not argument.startswith("-") or argument == "-" or NEGATIVE_NUMBER.match(argument):
                continue
            name = argument.split("=", 1)[0]
            if name in known or (name.startswith("--") and any(k.startswith(name) for k in known)):
                continue
            unknown.append(name)
        return unknown
