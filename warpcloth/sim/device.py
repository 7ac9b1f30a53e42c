"""One device rule for the whole library.

Every public builder (:func:`~warpcloth.sim.grid.build_grid_cloth`, :func:`~warpcloth.sim.model.build_model`,
:class:`~warpcloth.sim.control.Control`, the scenarios) resolves its ``device`` argument here, once, to a
``wp.Device`` that the model then carries: ``None`` means Warp's current device (``wp.get_device()``,
the CPU unless a script chose otherwise); ``"cuda"`` the first GPU. Only the command line picks a
default of its own (``cpu``).
"""

from __future__ import annotations

import os
import sys
import tempfile

import warp as wp

from warpcloth.errors import WarpclothError

# Warp logs a banner when it starts and a line for every module it loads, on stdout, which warpcloth
# keeps for results (``--json``). warpcloth starts Warp here (every builder resolves its device in
# this module), so Warp's documented log level is set here, before Warp initialises or loads a
# module: warnings and errors only, unless WARPCLOTH_WARP_VERBOSE is set (or ``--verbose``).
if not os.environ.get("WARPCLOTH_WARP_VERBOSE"):
    wp.config.log_level = wp.LOG_WARNING


def resolve_device(device=None) -> wp.Device:
    """The ``wp.Device`` named by ``device`` (None: Warp's current device; ``"cuda"``: the first
    GPU), or a :class:`WarpclothError` naming the value and the devices that exist."""
    if device is None:
        return wp.get_device()
    if isinstance(device, wp.Device):
        return device
    available = [str(d) for d in wp.get_devices()]
    if not isinstance(device, str):
        raise WarpclothError(
            f"device must be a device name such as 'cpu' or 'cuda:0', got {device!r} (available: "
            f"{', '.join(available)})"
        )
    name = device.strip()
    if name == "cuda":
        cuda = [d for d in available if d.startswith("cuda")]
        if not cuda:
            raise WarpclothError(
                f"device {device!r} is not available: no CUDA device found (available: {', '.join(available)})"
            )
        name = cuda[0]
    if name not in available:
        raise WarpclothError(f"device {device!r} is not available (available: {', '.join(available)})")
    return wp.get_device(name)


def available_memory(device) -> int:
    """Bytes that ``device`` can still allocate: free GPU memory, or the host's available RAM."""
    d = resolve_device(device)
    if d.is_cuda:
        return int(d.free_memory)
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
        return 2**63


def require_memory(what: str, needed: int, device) -> None:
    """Refuse, before allocating, a ``needed``-byte ``what`` that ``device`` cannot hold."""
    have = available_memory(device)
    if needed > have:
        raise WarpclothError(
            f"{what} needs about {_bytes(needed)} but {resolve_device(device)} has {_bytes(have)} available"
        )


def _bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"):
        if n < 1024 or unit == "EiB":
            return f"{n:.3g} {unit}"
        n /= 1024.0
    return f"{n:.3g} EiB"  # pragma: no cover


def device_name(device=None) -> str:
    """The name of :func:`resolve_device`'s device, e.g. ``"cpu"`` or ``"cuda:0"``."""
    return str(resolve_device(device))


__all__ = ["available_memory", "device_name", "require_memory", "resolve_device"]


def init_warp(verbose: bool = False) -> None:
    """``wp.init()`` without Warp's start-up lines on stderr (e.g. "CUDA driver not found",
    printed by its native library) unless ``verbose``; they are shown if init fails."""
    if verbose:
        wp.config.quiet = False
        if hasattr(wp, "LOG_INFO"):
            wp.config.log_level = wp.LOG_INFO
        wp.init()
        return
    wp.config.quiet = True
    try:
        from warp import context as _ctx  # noqa: PLC0415 (Warp's runtime, read only to tell whether Warp has started)

        if getattr(_ctx, "runtime", None) is not None:
            return
    except ImportError:  # pragma: no cover - Warp layout changed
        pass
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):
        wp.init()
        return
    with tempfile.TemporaryFile() as captured:
        os.dup2(captured.fileno(), 2)
        try:
            wp.init()
        except BaseException:
            os.dup2(saved, 2)
            captured.seek(0)
            sys.stderr.write(captured.read().decode("utf-8", "replace"))
            raise
        finally:
            os.dup2(saved, 2)
            os.close(saved)


# -- reproducible atomics on CUDA ---------------------------------------------------------------
#: The Python packages whose Warp kernels a step launches: warpcloth's own and the Warp library's
#: (warp.sparse, warp.optim.linear, warp.utils live under warp._src).
_KERNEL_PACKAGES = ("warpcloth", "warp")


def _kernel_modules() -> list:
    """The Warp modules (``wp.Kernel.module``) of every kernel defined in an imported module of
    :data:`_KERNEL_PACKAGES`, but those whose module says ``NOT_DETERMINISTIC`` (why)."""
    modules = {}
    for name, pymod in list(sys.modules.items()):
        if pymod is None or name.split(".")[0] not in _KERNEL_PACKAGES:
            continue
        if isinstance(getattr(pymod, "NOT_DETERMINISTIC", None), str):
            continue
        for value in list(vars(pymod).values()):
            if isinstance(value, wp.Kernel):
                modules[value.module.name] = value.module
    return list(modules.values())


def set_deterministic(enabled: bool) -> None:
    """Bit-reproducible results on CUDA (True) or Warp's default atomics (False), process-wide.

    On a GPU, forces are summed into each particle with floating-point atomics whose order changes
    from launch to launch, so two runs of the same scene (or a captured graph and plain launches)
    agree only to rounding, which grows over the steps. True sets Warp's
    ``DeterministicMode.RUN_TO_RUN`` (Warp >= 1.15: those sums are recorded, sorted and reduced in
    a fixed order) for every kernel module loaded now and created later, so repeated runs on the
    same GPU model are bit-identical; it costs speed (measured: docs/gpu.md,
    "Reproducibility"). Self-collision's kernels stay outside it (``NOT_DETERMINISTIC`` in
    :mod:`warpcloth.kernels.self_contact`): with self-collision on, a CUDA run is reproducible to
    rounding only. The CPU backend runs a launch's threads in order and is bit-reproducible
    either way; changing the setting recompiles the modules it touches once (then cached)."""
    if not isinstance(enabled, bool):
        raise WarpclothError(f"deterministic must be True or False, got {enabled!r:.80}")
    mode_type = getattr(wp, "DeterministicMode", None)
    if mode_type is None:
        if enabled:
            raise WarpclothError(
                f"deterministic runs need Warp >= 1.15 (its DeterministicMode); this is Warp {wp.config.version}"
            )
        return
    mode = mode_type.RUN_TO_RUN if enabled else mode_type.NOT_GUARANTEED
    if wp.config.deterministic == mode:
        return
    wp.config.deterministic = mode
    for module in _kernel_modules():
        if module.options.get("deterministic") != mode:
            wp.set_module_options({"deterministic": mode}, module=module)


def deterministic() -> bool:
    """Whether :func:`set_deterministic` is on (Warp's ``config.deterministic`` is not NOT_GUARANTEED)."""
    mode_type = getattr(wp, "DeterministicMode", None)
    return mode_type is not None and wp.config.deterministic != mode_type.NOT_GUARANTEED
