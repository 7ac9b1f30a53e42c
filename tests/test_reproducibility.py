"""Reproducible runs: Warp's deterministic atomics for CUDA (``set_deterministic``, the
``deterministic`` run parameter). The GPU side (graph replay bit-identical to plain launches, and
within rounding of the default atomics) is in tests/test_contract.py and tests/test_integrators.py."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from warpcloth import Simulator, WarpclothError, build_grid_cloth
from warpcloth.kernels import forces
from warpcloth.scenarios import flag
from warpcloth.sim.device import deterministic, set_deterministic

needs_mode = pytest.mark.skipif(not hasattr(wp, "DeterministicMode"), reason="Warp < 1.15 has no DeterministicMode")


@needs_mode
def test_set_deterministic_sets_every_kernel_module_and_back():
    from warpcloth.sim.device import _kernel_modules

    kernel_modules = set(_kernel_modules())
    names = {m.name for m in kernel_modules}
    assert forces.eval_springs.module.name in names and "warp.sparse" in names  # ours and Warp's
    assert not deterministic()
    try:
        set_deterministic(True)
        assert deterministic() and wp.config.deterministic == wp.DeterministicMode.RUN_TO_RUN
        for module in kernel_modules:
            assert module.options["deterministic"] == wp.DeterministicMode.RUN_TO_RUN, module.name
    finally:
        set_deterministic(False)
    assert not deterministic() and wp.config.deterministic == wp.DeterministicMode.NOT_GUARANTEED
    for module in kernel_modules:
        assert module.options["deterministic"] == wp.DeterministicMode.NOT_GUARANTEED, module.name


@pytest.mark.parametrize("value", ["on", 1, None])
def test_bad_deterministic_values_are_one_line_errors(value):
    with pytest.raises(WarpclothError, match="deterministic must be True or False"):
        set_deterministic(value)
    model = build_grid_cloth(4, 4, 1.0, 1.0, 0.1, device="cpu")
    if value is not None:  # None is the Simulator's "leave it as it is"
        with pytest.raises(WarpclothError, match="deterministic must be True, False or None"):
            Simulator(model, deterministic=value)


def test_the_cpu_ignores_it_and_is_bit_reproducible():
    """On the CPU the setting changes nothing (no recompilation either): two runs agree to the bit."""
    before = wp.config.deterministic if hasattr(wp, "DeterministicMode") else None
    a = flag.build(rows=6, cols=7, integrator="xpbd", device="cpu", deterministic=True)
    b = flag.build(rows=6, cols=7, integrator="xpbd", device="cpu", deterministic=False)
    assert (wp.config.deterministic if before is not None else None) == before
    a.simulate(24)
    b.simulate(24)
    q = a.state.particle_q.numpy()
    assert np.array_equal(q, b.state.particle_q.numpy())
    assert np.abs(q - a.model.particle_q.numpy()).max() > 1e-4  # it moved


@needs_mode
def test_every_covered_kernel_compiles_in_deterministic_mode_for_cuda():
    """Warp's deterministic mode refuses some kernels at code generation (an array both stored to and
    updated atomically in one kernel, as the metrics' non-finite flag was: `warpcloth run --device
    cuda --deterministic on` failed on a GPU). The CUDA source of every module set_deterministic
    covers is generated here, without a GPU; self-contact stays outside (NOT_DETERMINISTIC)."""
    import importlib
    import pkgutil

    import warpcloth
    from warpcloth.kernels import self_contact
    from warpcloth.sim.device import _kernel_modules

    try:
        from warp._src.context import ModuleBuilder
    except ImportError:  # pragma: no cover - Warp moved its builder
        pytest.skip(f"Warp {wp.config.version} has no warp._src.context.ModuleBuilder")
    for info in pkgutil.walk_packages(warpcloth.__path__, "warpcloth."):
        importlib.import_module(info.name)
    ours = [m for m in _kernel_modules() if m.name.startswith("warpcloth.")]
    names = {m.name for m in ours}
    assert "warpcloth.kernels.metrics" in names and "warpcloth.kernels.forces" in names
    try:
        set_deterministic(True)
        assert (
            next(v for v in vars(self_contact).values() if isinstance(v, wp.Kernel)).module.options["deterministic"]
            == wp.DeterministicMode.NOT_GUARANTEED
        )
        for module in ours:
            assert module.options["deterministic"] == wp.DeterministicMode.RUN_TO_RUN
            source = ModuleBuilder(module, module.options | {"output_arch": None}, target="cuda").codegen("cuda")
            assert len(source) > 1000, module.name
    finally:
        set_deterministic(False)


def test_every_kernel_module_compiles_without_adjoints():
    # nothing differentiates through warpcloth's kernels, and Warp's adjoint code roughly doubles a module's
    # compile time (CI compiles every module from an empty cache); kernels/ccd.py compiled it until now
    import importlib
    import pkgutil

    import warpcloth.kernels as package

    names = [m.name for m in pkgutil.iter_modules(package.__path__, package.__name__ + ".")]
    assert len(names) > 15
    for name in names:
        importlib.import_module(name)
        assert wp.get_module(name).options["enable_backward"] is False, name
