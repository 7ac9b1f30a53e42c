"""CPU vs CUDA benchmark of every integrator on the sheet scenario.

    python bench/devices.py --sizes 32,64,128,256 --roofline --out bench.csv --plot bench.png

Same as ``warpcloth bench``; see ``warpcloth.lab.bench`` for what is measured.
"""

import sys

from warpcloth.cli.bench import main

if __name__ == "__main__":
    sys.exit(main())
