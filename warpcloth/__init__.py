"""warpcloth: a mass-spring cloth simulator and integrator laboratory on NVIDIA Warp.

The same kernels run on the CPU and on a CUDA GPU. Typical use::

    import warpcloth
    from warpcloth.scenarios import sheet
    sim = sheet.build(rows=32, cols=32, integrator="rk4")   # a Simulator: it steps
    result = warpcloth.RunHarness(sim).run(duration=5.0)    # the run harness: frames, timing, verdicts
    print(result.to_json())

The names below load their modules on first use (``import warpcloth`` imports no Warp: the
``warpcloth --version`` line and the CLI's start stay fast). Warp's quiet configuration (no banner,
no module-load lines on stdout, which warpcloth keeps for results; ``WARPCLOTH_WARP_VERBOSE=1``
keeps Warp's own) is applied as soon as Warp is imported, by anyone, before it initialises.
"""

import importlib
import importlib.abc
import importlib.machinery
import os
import sys

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
    "Simulator": "warpcloth.simulator",
    **dict.fromkeys(("RunHarness", "RunResult"), "warpcloth.run.harness"),
    "State": "warpcloth.sim.state",
}


def _quiet(wp) -> None:
    """Warp's log level to warnings and no banner (unless WARPCLOTH_WARP_VERBOSE is set)."""
    if os.environ.get("WARPCLOTH_WARP_VERBOSE"):
        return
    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_WARNING
    wp.config.quiet = True


class _QuietOnImport(importlib.abc.MetaPathFinder):
    """Applies :func:`_quiet` right after ``warp`` is imported (then leaves ``sys.meta_path``)."""

    def find_spec(self, fullname, path, target=None):
        if fullname != "warp":
            return None
        sys.meta_path[:] = [f for f in sys.meta_path if f is not self]
        spec = importlib.machinery.PathFinder.find_spec(fullname, path)
        if spec is None or spec.loader is None:
            return spec
        run = spec.loader.exec_module

        def exec_module(module):
            run(module)
            _quiet(module)

        spec.loader.exec_module = exec_module
        return spec


if "warp" in sys.modules:
    _quiet(sys.modules["warp"])
elif not any(isinstance(f, _QuietOnImport) for f in sys.meta_path):
    sys.meta_path.insert(0, _QuietOnImport())


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
    "ClothModel",
    "ColliderTrack",
    "Control",
    "MeshCollider",
    "Integrator",
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
    "build_grid_cloth",
    "build_mesh_cloth",
    "load_mesh",
    "load_mesh_collider",
    "expected_spring_counts",
    "integrator_names",
    "make_integrator",
    "__version__",
]
