"""Write cape.obj: the built-in cape of the ``mesh`` scenario (a 20 x 16 grid wrapped around the
shoulders, a ``shoulders`` vertex group, UVs), for ``warpcloth run mesh --mesh``. The package
ships it (``examples/cape.obj``, ``warpcloth list --examples``); this writes it afresh.

    python -m warpcloth.examples.make_cape [OUT.obj]     (default: cape.obj in the current folder)
"""

import sys

import numpy as np

from warpcloth.io.meshio import write_obj
from warpcloth.scenarios.mesh import make_cape


def main(argv=None) -> str:
    argv = sys.argv[1:] if argv is None else argv
    out = argv[0] if argv else "cape.obj"
    cape = make_cape()
    uv = np.zeros((cape.vertices.shape[0], 2))
    uv[cape.triangles.ravel()] = cape.uv.reshape(-1, 2)  # per-vertex UVs from the corners (no seams)
    write_obj(out, cape.vertices, cape.triangles, uv=uv, groups=cape.groups)
    return out


if __name__ == "__main__":
    print(main())
