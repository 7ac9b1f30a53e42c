"""warpcloth: a mass-spring cloth simulator and integrator laboratory on NVIDIA Warp.

The same kernels run on the CPU and on a CUDA GPU. Typical use::

    import warpcloth
    from warpcloth.scenarios import sheet
    sim = sheet.build(rows=32, cols=32, integrator="rk4")   # a Simulator: it steps
    result = warpcloth.RunHarness(sim).run(duration=5.0)    # the run harness: frames, timing, verdicts
    print(result.to_json())
"""

import os

import warp as wp

from warpcloth.version import __version__  # noqa: E402

# Warp prints a banner and per-module load lines on stdout; warpcloth keeps stdout for results.
if not os.environ.get("WARPCLOTH_WARP_VERBOSE"):
    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_WARNING
    wp.config.quiet = True

from warpcloth.sim.colliders import Box, Capsule, ColliderTrack, MeshCollider, Plane, Sphere  # noqa: E402
from warpcloth.errors import WarpclothError  # noqa: E402
from warpcloth.sim.control import Control, WindSchedule  # noqa: E402
from warpcloth.integrators import Integrator, integrator_names, make_integrator  # noqa: E402
from warpcloth.sim.grid import build_grid_cloth, expected_spring_counts  # noqa: E402
from warpcloth.sim.model import BendModel, ClothModel, SpringParams, SpringType  # noqa: E402
from warpcloth.sim.mesh import TriangleMesh, build_mesh_cloth  # noqa: E402
from warpcloth.io.meshio import load_mesh, load_mesh_collider  # noqa: E402
from warpcloth.sim.pins import PinTrack  # noqa: E402
from warpcloth.simulator import Simulator  # noqa: E402
from warpcloth.run.harness import RunHarness, RunResult  # noqa: E402
from warpcloth.sim.state import State  # noqa: E402

__all__ = [
    "BendModel", "Box", "Capsule", "ClothModel", "ColliderTrack", "Control", "MeshCollider", "Integrator", "PinTrack", "Plane", "RunHarness", "RunResult", "Simulator", "Sphere", "SpringParams", "SpringType",
    "State", "TriangleMesh", "WarpclothError", "WindSchedule", "build_grid_cloth", "build_mesh_cloth", "load_mesh", "load_mesh_collider", "expected_spring_counts", "integrator_names",
    "make_integrator", "__version__",
]
