"""``python -m tolsynth``: the command line."""

import sys

from tolsynth.cli import main

if __name__ == "__main__":
    sys.exit(main())
