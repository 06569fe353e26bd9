import sys

from calibproj.cli import main

sys.exit(main())
