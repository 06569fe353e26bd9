"""The ``calibproj`` command line: one program, one subcommand per stage.

Each subcommand lives in ``calibproj.commands.<name>`` with ``add_arguments(parser)``
and ``run(args) -> int``; those modules import heavy libraries only inside ``run``
so that ``--help`` stays instant.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from calibproj.io.output_folder import OutputBusyError

# name -> module; the order is the order of the workflow.
COMMANDS = {
    "generate": "calibproj.commands.generate",
    "simulate": "calibproj.commands.simulate",
    "detect": "calibproj.commands.detect",
    "calibrate": "calibproj.commands.calibrate",
    "compare": "calibproj.commands.compare",
    "evaluate": "calibproj.commands.evaluate",
    "demo": "calibproj.commands.demo",
}


class CommandError(Exception):
    """A bad invocation or input: reported as one line, exit status 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="calibproj",
        description="Calibrate a camera network from projected multi-scale markers.",
    )
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, module_name in COMMANDS.items():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as error:
            if error.name != module_name:
                raise
            continue  # a stage not built yet
        doc = (module.__doc__ or "").strip()
        summary = doc.splitlines()[0] if doc else name
        sub = subparsers.add_parser(
            name, help=summary, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter
        )
        module.add_arguments(sub)
        sub.set_defaults(run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose + 1, 2)
    logging.basicConfig(level=level, format="%(message)s")
    try:
        return int(args.run(args) or 0)
    except OutputBusyError as error:
        print(f"calibproj {args.command}: error: {error}", file=sys.stderr)
        return 1
    except (CommandError, ValueError, FileNotFoundError, RuntimeError) as error:
        print(f"calibproj {args.command}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"calibproj {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
