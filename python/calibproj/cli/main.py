"""The ``calibproj`` command line: one program, one subcommand per stage.

Each subcommand lives in ``calibproj.cli.<name>`` with ``add_arguments(parser)``
and ``run(args) -> int``; those modules import heavy libraries only inside ``run``
so that ``--help`` stays instant.

Exit status (README, "Exit status"): ``EXIT_OK`` 0 when the run did all it was asked;
``EXIT_USAGE`` 2 for a bad invocation or input (argparse's errors, ``CommandError``,
``ValueError`` and ``OSError``: a missing or malformed file, an output that cannot be
written), reported in one line naming the file; ``EXIT_FAILURE`` 1 for any other
failure: a run that finished without every camera (the commands return it), another
run writing the same output or an external program that failed (``RuntimeError``, one
line), or an internal error (any other exception, reported with its traceback);
``EXIT_INTERRUPTED`` 130 on Ctrl-C, and on SIGTERM (``kill``, a service manager), which
ends a run the same way: outputs are left as they were before it.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import signal
import sys
import threading
import traceback
from collections.abc import Iterator
from contextlib import contextmanager

from calibproj.cli.parser import SuggestingArgumentParser
from calibproj.common.interruption import caused_by_interrupt
from calibproj.version import __version__

# name -> module; the order is the order of the workflow.
COMMANDS = {
    "generate": "calibproj.cli.generate",
    "simulate": "calibproj.cli.simulate",
    "detect": "calibproj.cli.detect",
    "intrinsics": "calibproj.cli.intrinsics",
    "calibrate": "calibproj.cli.calibrate",
    "compare": "calibproj.cli.compare",
    "evaluate": "calibproj.cli.evaluate",
    "check": "calibproj.cli.check",
    "capture": "calibproj.cli.capture",
    "demo": "calibproj.cli.demo",
    "study": "calibproj.cli.study",
}

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2  # also what argparse exits with on a bad invocation
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as shells report it


class CommandError(Exception):
    """A bad invocation or input: reported as one line, exit status 2."""


def build_parser() -> SuggestingArgumentParser:
    parser = SuggestingArgumentParser(
        prog="calibproj",
        description="Calibrate a camera network from projected multi-scale markers.",
    )
    parser.add_argument("--version", action="version", version=f"calibproj {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True,
                                       help="the stage to run; calibproj COMMAND --help lists its options")
    for name, module_name in COMMANDS.items():
        module = importlib.import_module(module_name)
        doc = (module.__doc__ or "").strip()
        summary = doc.splitlines()[0] if doc else name
        sub = subparsers.add_parser(
            name, help=summary, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter
        )
        module.add_arguments(sub)
        # -v is taken after the command too, where a user adds it to the line he ran.
        sub.add_argument("-v", "--verbose", action="count", default=0, dest="command_verbose",
                         help="more log output (-vv for debug); before the command as well")
        sub.usage = compact_usage(sub)
        sub.siblings = subparsers.choices
        sub.set_defaults(run=module.run, command_parser=sub)
    return parser


def compact_usage(parser: argparse.ArgumentParser) -> str:
    """``calibproj calibrate [VIDEOS_DIR] --out DIR [options]``: the positional arguments
    and required options; the options are listed, grouped, below it."""
    parts = ["%(prog)s"]
    formatter = parser._get_formatter()
    for action in parser._actions:
        if not action.option_strings:
            parts.append(formatter._format_args(action, action.dest.upper()))
        elif action.required:
            parts.append(f"{action.option_strings[0]} {action.metavar or action.dest.upper()}")
    return " ".join(parts + ["[options]"])


def parse_arguments(parser: SuggestingArgumentParser, argv: list[str] | None) -> argparse.Namespace:
    """``parser.parse_args``, with arguments unknown to the subcommand reported by the
    subcommand's parser (its usage, its options suggested)."""
    args, extras = parser.parse_known_args(argv)
    if extras:
        command_parser = args.command_parser
        own = set(command_parser.arguments)
        reporter = command_parser if all(extra in own for extra in extras) else parser
        reporter.error(f"unrecognized arguments: {' '.join(extras)}")
    return args


class _Interruptions:
    """Ctrl-C (SIGINT) and SIGTERM raise KeyboardInterrupt, and are remembered.

    Python raises a signal's exception wherever the main thread is at the moment, and
    code that is not ours may swallow it there: OpenCV's loader runs its configuration
    under bare ``except:`` clauses, and pybind11 clears an error raised while it
    converts an argument (``os.fspath``) and reports a TypeError instead. Remembered,
    an interruption is reported as one whatever error it became."""

    def __init__(self) -> None:
        self.received = False

    def __call__(self, signal_number: int, frame: object) -> None:
        self.received = True
        raise KeyboardInterrupt

    @contextmanager
    def installed(self) -> Iterator[None]:
        """The handler, while the block runs (signal handlers can only be set from the
        main thread; elsewhere nothing changes)."""
        if threading.current_thread() is not threading.main_thread():
            yield
            return
        import cv2  # noqa: F401  # before the handler: its loader would swallow an interruption
        previous = {number: signal.signal(number, self) for number in (signal.SIGINT, signal.SIGTERM)}
        try:
            yield
        finally:
            for number, handler in previous.items():
                signal.signal(number, handler)


def main(argv: list[str] | None = None) -> int:
    try:
        return _run(argv)
    except KeyboardInterrupt:  # while the command line is read, before its command runs
        print("calibproj: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as error:
        # The command modules' imports, interrupted (see calibproj.common.interruption).
        if not caused_by_interrupt(error):
            raise
        print("calibproj: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def _run(argv: list[str] | None) -> int:
    parser = build_parser()
    args = parse_arguments(parser, argv)
    # Recorded in the outputs that say how they were made (provenance.json).
    args.command_line = ["calibproj", *(sys.argv[1:] if argv is None else argv)]
    level = logging.WARNING - 10 * min(args.verbose + args.command_verbose + 1, 2)
    logging.basicConfig(level=level, format="%(message)s")
    prefix = f"calibproj {args.command}"
    interruptions = _Interruptions()
    try:
        from tqdm.contrib.logging import logging_redirect_tqdm

        # Log lines go through tqdm.write while bars are open: never in the middle of a bar.
        with interruptions.installed(), logging_redirect_tqdm():
            return int(args.run(args) or EXIT_OK)
    except KeyboardInterrupt:
        print(f"{prefix}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as error:
        if interruptions.received or caused_by_interrupt(error):  # an interruption in disguise
            print(f"{prefix}: interrupted", file=sys.stderr)
            return EXIT_INTERRUPTED
        if isinstance(error, (CommandError, ValueError, OSError)):
            print(f"{prefix}: error: {error}", file=sys.stderr)
            return EXIT_USAGE
        if isinstance(error, RuntimeError):
            print(f"{prefix}: error: {error}", file=sys.stderr)
            return EXIT_FAILURE
        traceback.print_exc()
        print(f"{prefix}: internal error: {type(error).__name__}: {error}", file=sys.stderr)
        return EXIT_FAILURE


if __name__ == "__main__":
    sys.exit(main())
