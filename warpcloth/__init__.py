"""warpcloth: a mass-spring cloth simulator and integrator laboratory on NVIDIA Warp.

The same kernels run on the CPU and on a CUDA GPU. Typical use::

    import warpcloth
    from warpcloth.scenarios import sheet
    sim = sheet.build(rows=32, cols=32, integrator="rk4")   # a Simulator: it steps
    result = warpcloth.RunHarness(sim).run(duration=5.0)    # the run harness: frames, timing, verdicts
    print(result.to_json())

The names below load their modules on first use (``import warpcloth`` imports no Warp: the
``warpcloth --version`` line and the CLI's start stay fast). Warp is quieted where warpcloth starts
it (:mod:`warpcloth.sim.device`); importing this package changes nothing of Warp's.
"""

import importlib

from warpcloth.version import __version__

#: The package face: name -> the module that defines it (imported on first use).
_FACE = {
    **dict.fromkeys(("Box", "Capsule", "ColliderTrack", "MeshCollider", "Plane", "Sphere"), "warpcloth.sim.colliders"),
    "WarpclothError": "warpcloth.errors",
    **dict.fromkeys(("Control", "WindSchedule"), "warpcloth.sim.control"),
    **dict.fromkeys(("Integrator", "integrator_names", "make_integrator"), "warpcloth.integrators"),
    **dict.fromkeys(("build_grid_cloth", "expected_spring_counts"), "warpcloth.sim.grid"),
    **dict.fromkeys(("BendModel", "ClothModel", "SpringParams", "SpringType"), "warpcloth.sim.model"),
    **dict.fromkeys(("TriangleMesh", "build_mesh_cloth"), "warpcloth.sim.mesh"),
    **dict.fromkeys(("load_mesh", "load_mesh_collider"), "warpcloth.io.meshio"),
    "PinTrack": "warpcloth.sim.pins",
    "ClothBuilder": "warpcloth.sim.builder",
    "Simulator": "warpcloth.simulator",
    **dict.fromkeys(("RunHarness", "RunResult"), "warpcloth.run.harness"),
    "State": "warpcloth.sim.state",
}


def __getattr__(name):
    module = _FACE.get(name)
    if module is None:
        raise AttributeError(f"module 'warpcloth' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__():
    return sorted([*globals(), *_FACE])


__all__ = [
    "BendModel",
    "Box",
    "Capsule",
    "ClothBuilder",
    "ClothModel",
    "ColliderTrack",
    "Control",
    "Integrator",
    "MeshCollider",
    "PinTrack",
    "Plane",
    "RunHarness",
    "RunResult",
    "Simulator",
    "Sphere",
    "SpringParams",
    "SpringType",
    "State",
    "TriangleMesh",
    "WarpclothError",
    "WindSchedule",
    "__version__",
    "build_grid_cloth",
    "build_mesh_cloth",
    "expected_spring_counts",
    "integrator_names",
    "load_mesh",
    "load_mesh_collider",
    "make_integrator",
]
