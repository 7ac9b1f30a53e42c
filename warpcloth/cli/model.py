"""The flags of a model and its integrator, shared by ``warpcloth run`` and ``warpcloth max-dt``:
the run parameters (:mod:`warpcloth.run.params`), the
integrators' options (:class:`~warpcloth.integrators.Option`), and the ScenarioConfig they give
(:func:`config_from_args`), with the checks that name a flag rather than fail later."""

from __future__ import annotations

import argparse

import numpy as np

from warpcloth.errors import WarpclothError, require_positive
from warpcloth.integrators import (
    all_options,
    check_integrator_name,
    integrator_class,
    option_help,
    option_owners,
)
from warpcloth.run.params import (
    BY_NAME,
    add_flags,
    check_applies,
    check_self_collision_settings,
    cli_value,
    config_values,
    params_for,
)


def add_model_arguments(p: argparse.ArgumentParser, command: str = "max-dt", exclusive: dict | None = None) -> None:
    """The flags of ``command``'s run parameters (:mod:`warpcloth.run.params`) and the integrators'
    options (:class:`~warpcloth.integrators.Option`)."""
    add_flags(p, command, skip=("scenario",), exclusive=exclusive)
    add_integrator_options(p)


def add_integrator_options(p: argparse.ArgumentParser) -> None:
    """One flag per integrator option, declared by the integrators themselves."""
    group = p.add_argument_group("integrator options")
    for name, (opt, _) in all_options().items():
        choices = [o.choices for o in option_owners(name).values()]
        kwargs = {"choices": list(dict.fromkeys(c for cs in choices for c in cs))} if all(choices) else {}
        group.add_argument(
            opt.flag,
            dest="opt_" + name,
            type=str,
            default=None,
            metavar=opt.type.__name__.upper(),
            help=option_help(name),
            **kwargs,
        )


def integrator_options_from_args(integrator: str, args) -> dict:
    """Options given on the command line for ``integrator``; an option it does not take is an error."""
    taken = {o.name: o for o in integrator_class(integrator).options}
    out = {}
    for name, (opt, owners) in all_options().items():
        value = getattr(args, "opt_" + name, None)
        if value is None:
            continue
        if name not in taken:
            raise WarpclothError(
                f"{opt.flag} does not apply to integrator {integrator!r} (it applies to {', '.join(owners)})"
            )
        out[name] = taken[name].parse(value)  # the integrator's own declaration (its check and type)
    return out


def param_values(args, command: str) -> dict:
    """The run parameters given on the command line, by name (unset: None)."""
    return {p.name: cli_value(p, args) for p in params_for(command) if not p.positional}


def config_from_args(scenario, args, command: str = "run"):
    """A ScenarioConfig from parsed flags (unset flags keep the scenario defaults)."""
    values = param_values(args, command)
    if values.get("integrator") is not None:
        check_integrator_name(values["integrator"], flag="--integrator")
    integrator = values.get("integrator") or scenario.defaults.integrator
    if values.get("size") is not None and (values.get("rows") is not None or values.get("cols") is not None):
        raise WarpclothError("give either --size or --rows and --cols, not both")
    check_applies(values, scenario.is_mesh, scenario.name)
    if values.get("device") is None:  # the scenario's (a scenario file's [run] device), else the CLI's default
        values["device"] = scenario.defaults.device or BY_NAME["device"].default
    kwargs = config_values(values)
    kwargs.update(integrator=integrator, integrator_options=integrator_options_from_args(integrator, args))
    cfg = scenario.config(**kwargs)
    on = scenario.self_collision_settings(cfg) is not None  # a bad value is refused as such first, on or off
    check_self_collision_settings(values, on, scenario.name)
    num_frames = getattr(args, "num_frames", None)
    if num_frames is not None:
        require_positive("fps", cfg.fps, "1/s")
        if num_frames < 1:
            raise WarpclothError(f"--num-frames must be >= 1, got {num_frames}")
        cfg.duration = num_frames / cfg.fps
    return cfg


def check_spacing(scenario, cfg) -> None:
    """Refuse a cloth whose particles float32 cannot tell apart (e.g. ``--height 1e-30``),
    naming the flag, rather than failing later on springs of rest length 0."""
    try:
        rows, cols, width, height = int(cfg.rows), int(cfg.cols), float(cfg.width), float(cfg.height)
        origin = [float(v) for v in scenario.origin(cfg)]
    except (TypeError, ValueError):
        return  # the builder names the bad value
    extent = max(abs(v) for v in origin) + max(abs(width), abs(height))
    if not np.isfinite(extent):
        return
    ulp = float(np.spacing(np.float32(extent)))
    for flag, size, n in (("--width", width, cols), ("--height", height, rows)):
        if n >= 2 and size > 0 and size / (n - 1) <= ulp:
            raise WarpclothError(
                f"{flag} {size:g} m over {n} particles puts neighbours {size / (n - 1):.3g} m apart, below float32's "
                f"resolution ({ulp:.3g} m) at the cloth's position, so they would coincide; use at least "
                f"{4 * ulp * (n - 1):.2g} m"
            )


class DefaultDtExplained:
    """Turns "dt must be > 0 s, got 0.0" from a *computed* default dt (the user gave none) into
    a message naming the flags the default came from (``--mass 1e30`` underflows it)."""

    FLAGS = tuple(
        (p.name, p.flag)
        for p in params_for("run")
        if p.name in ("mass", "drag") or p.name.startswith(("stiffness", "damping"))
    )

    def __init__(self, args):
        self.args = args

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None or not issubclass(exc_type, WarpclothError) or getattr(self.args, "dt", None) is not None:
            return False
        text = str(exc)
        if not text.startswith("dt must be"):
            return False
        given = []
        for attr, flag in self.FLAGS:
            value = getattr(self.args, attr, None)
            if value is not None:
                shown = ",".join(f"{v:g}" for v in value) if isinstance(value, tuple) else f"{value:g}"
                given.append(f"{flag} {shown}")
        cause = " ".join(given) if given else "the scenario's parameters"
        got = text.split("got", 1)[-1].strip().split()[0] if "got" in text else "?"
        raise WarpclothError(
            f"the integrator's default time step computed from {cause} is {got} s, not a usable dt "
            "(the stability estimate under- or overflows at these values); use values nearer the defaults, or give --dt"
        ) from None


__all__ = [
    "DefaultDtExplained",
    "add_model_arguments",
    "check_spacing",
    "config_from_args",
    "integrator_options_from_args",
    "param_values",
]
