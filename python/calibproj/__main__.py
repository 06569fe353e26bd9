"""``python -m calibproj`` and the ``calibproj`` command: the command line.

The command line's module is imported here, under a handler of its own, so that Ctrl-C
at any moment of the start gives the one line every interruption gives.
"""

import sys


def run() -> int:
    try:
        from calibproj.cli.main import main
    except KeyboardInterrupt:
        print("calibproj: interrupted", file=sys.stderr)
        return 130
    except Exception as error:
        from calibproj.common.interruption import caused_by_interrupt

        if not caused_by_interrupt(error):
            raise
        print("calibproj: interrupted", file=sys.stderr)
        return 130
    return main()


if __name__ == "__main__":
    sys.exit(run())
