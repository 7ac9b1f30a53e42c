"""What made an output: versions, the run's parameters, the device, the date, the command line.

Stored in a USD layer's ``customLayerData`` (under ``warpcloth``) and in the HTML player's data.
"""

from __future__ import annotations

import datetime
import os
import platform
import shlex
import socket
import sys

import warp as wp

from warpcloth.version import __version__


def command_line(argv=None, prefix=("warpcloth",)) -> str:
    """The command as typed (``warpcloth run ...``), quoted for a shell."""
    args = list(sys.argv[1:] if argv is None else argv)
    return shlex.join([*prefix, *args])


def provenance(sim, scenario: str, fps: float, argv=None, extra: dict | None = None, prefix=("warpcloth",)) -> dict:
    """A JSON-able dict about the run of ``sim`` (a :class:`~warpcloth.simulator.Simulator`)."""
    m = sim.model
    info = {
        "warpcloth_version": __version__,
        "warp_version": str(wp.config.version),
        "scenario": scenario,
        "integrator": sim.integrator.name,
        "integrator_options": dict(sim.integrator.option_values()),
        "dt": float(sim.dt),
        "fps": float(fps),
        "rows": int(m.rows),
        "cols": int(m.cols),
        "width": float(m.width),
        "height": float(m.height),
        "mass": float(m.total_mass),
        "particle_mass": float(m.particle_mass_value),
        "ks": {t.name.lower(): float(p.stiffness) for t, p in m.spring_params.items()},
        "kd": {t.name.lower(): float(p.damping) for t, p in m.spring_params.items()},
        "bend": str(getattr(m.bend, "value", m.bend)),
        "strain_limit": None if sim.strain_limiter is None else float(sim.strain_limiter.tau),
        # the limit applied: the user's, or the integrator's own (implicit_euler's strain_cap)
        "strain_limit_applied": None if sim.active_limiter is None else float(sim.active_limiter.tau),
        "device": str(m.device),
        "date": datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat(),
        "command_line": command_line(argv, prefix),
    }
    if extra:
        info.update(extra)
    return _jsonable(info)


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if hasattr(value, "item"):
        return value.item()
    return str(value)


def machine(device=None) -> dict:
    """Where a measurement ran, for a benchmark's rows and a study's report.

    Returns:
        ``host`` (host name), ``cpu`` (the CPU's model), ``cores`` (logical cores visible),
        ``gpu`` (the name of ``device`` when it is a CUDA device, else empty), ``gpus`` (every
        CUDA device, ``cuda:0 NAME``), ``driver`` (the CUDA driver's version, or None), ``warp``,
        ``python``, ``os`` and ``date`` (now, UTC, to the minute).
    """

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            cpu = next((line.split(":", 1)[1].strip() for line in fh if line.startswith("model name")), cpu)
    except OSError:
        pass
    gpu = ""
    if device is not None:
        try:
            d = wp.get_device(device)
            gpu = d.name if d.is_cuda else ""
        except Exception:
            gpu = ""
    gpus = []
    try:
        for d in wp.get_cuda_devices():
            gpus.append(f"{d} {wp.get_device(d).name}")
    except Exception:
        pass
    driver = None
    try:
        driver = wp.get_cuda_driver_version() if hasattr(wp, "get_cuda_driver_version") else None
    except Exception:
        driver = None
    return {
        "host": socket.gethostname(),
        "cpu": cpu,
        "cores": os.cpu_count(),
        "gpu": gpu,
        "gpus": gpus,
        "driver": driver,
        "warp": wp.config.version,
        "python": platform.python_version(),
        "os": platform.platform(),
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
    }
