"""``python -m warpcloth``: the ``warpcloth`` command line."""

import sys

from warpcloth.cli import main

if __name__ == "__main__":
    sys.exit(main())
