"""``python -m warpcloth.examples [DIR]``: copy the shipped examples (the XML test lists, the cape
mesh and its scenario file) into DIR (default ``./examples``), so that the README's commands
(``warpcloth sweep examples/quick.xml``, ``warpcloth run mesh --mesh examples/cape.obj``, ...) run
from any folder after ``pip install warpcloth``. Existing files are kept."""

import os
import shutil
import sys

#: The example files, by kind (``warpcloth list --examples`` prints them).
KINDS = {".xml": "test list", ".obj": "mesh", ".toml": "scenario file"}


def example_files() -> list[tuple[str, str]]:
    """(kind, path) of every shipped example file, by kind then name."""
    here = os.path.dirname(os.path.abspath(__file__))
    files = [
        (KINDS[os.path.splitext(n)[1]], os.path.join(here, n))
        for n in os.listdir(here)
        if os.path.splitext(n)[1] in KINDS
    ]
    order = list(KINDS.values())
    return sorted(files, key=lambda f: (order.index(f[0]), f[1]))


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0
    folder = argv[0] if argv else "examples"
    os.makedirs(folder, exist_ok=True)
    for kind, path in example_files():
        target = os.path.join(folder, os.path.basename(path))
        if os.path.exists(target):
            print(f"kept   {target} (exists)")
            continue
        shutil.copyfile(path, target)
        print(f"copied {target} ({kind})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
