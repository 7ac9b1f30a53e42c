"""``python -m warpcloth.cli``: the ``warpcloth`` command."""

import sys

from warpcloth.cli import main

if __name__ == "__main__":
    sys.exit(main())
