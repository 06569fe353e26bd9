"""``python -m calibproj``: the ``calibproj`` command line."""

import sys

from calibproj.cli import main

if __name__ == "__main__":
    sys.exit(main())
