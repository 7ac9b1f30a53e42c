"""Honest start-up figures: a run's compile time counts every Warp module the run loads (a
collider's included), measured in a fresh process against the time Warp itself spends loading."""

import json
import os
import subprocess
import sys
import textwrap

import pytest

#: Runs a scenario in a fresh process with Warp's Module.load timed, and prints the seconds of
#: every first load of a module (compiled or from the kernel cache) beside the run's compile_time.
_PROBE = textwrap.dedent("""
    import io, json, sys, time
    from contextlib import redirect_stdout
    from warp._src import context as ctx
    loads, first = {}, ctx.Module.load
    def load(self, device, *args, **kwargs):
        key = (self.name, str(device))
        if key in loads:
            return first(self, device, *args, **kwargs)
        t0 = time.perf_counter()
        try:
            return first(self, device, *args, **kwargs)
        finally:
            loads[key] = time.perf_counter() - t0
    ctx.Module.load = load
    from warpcloth.cli import main
    out = io.StringIO()
    with redirect_stdout(out):
        main(["run", *sys.argv[1:], "--json"])
    result = json.loads(out.getvalue())
    print(json.dumps({"compile_time": result["compile_time"], "loads": {k[0]: v for k, v in loads.items()}}))
""")


@pytest.mark.parametrize(
    "args",
    [
        ["drape", "--num-frames", "2"],
        ["tablecloth", "--num-frames", "2", "--size", "12"],
        ["drape", "--num-frames", "2", "-i", "vbd", "--size", "12"],
    ],
)
def test_compile_time_counts_every_module_the_run_loads(args):
    # the collider module used to load while the scenario built its control, before the timed
    # warm-up: a cold drape printed "+5.24 s compile" after 16 s of collider compilation
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    proc = subprocess.run([sys.executable, "-c", _PROBE, *args], capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    probe = json.loads(proc.stdout.strip().splitlines()[-1])
    loads = {name: s for name, s in probe["loads"].items() if name.startswith("warpcloth.")}
    assert "warpcloth.kernels.collide" in loads  # the run has colliders: their module is among the loads
    assert probe["compile_time"] >= sum(loads.values()), probe


def _python(code: str, **env) -> str:
    proc = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=300,
        env={**{k: v for k, v in os.environ.items() if k != "WARPCLOTH_WARP_VERBOSE"}, **env},
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


def test_version_answers_without_importing_warp():
    # `warpcloth --version` took 5-8 s: the package face imported Warp (about 1 s alone) and all of
    # warpcloth; now it is the version module and the CLI's top level (0.18 s on the build machine)
    out = _python(
        "import sys\nfrom warpcloth.cli import main\ntry:\n    main(['--version'])\nexcept SystemExit:\n    pass\n"
        "print('warp' in sys.modules, sorted(m for m in sys.modules if m.startswith('warpcloth')))"
    )
    assert out.splitlines()[0].startswith("warpcloth 0.1")
    imported, modules = out.splitlines()[1].split(" ", 1)
    assert imported == "False" and "warpcloth.sim" not in modules, out


def test_importing_warpcloth_leaves_warp_and_the_import_system_alone():
    # the package face used to put a sys.meta_path hook in every importer's process that patched
    # Warp's own loader; importing warpcloth now changes neither the import system nor Warp
    out = _python(
        "import sys\nfinders = list(sys.meta_path)\nimport warpcloth, warp as wp\n"
        "print(sys.meta_path == finders, wp.config.log_level == wp.LOG_INFO)"
    )
    assert out.split() == ["True", "True"]
    out = _python("import warpcloth\nprint(warpcloth.Simulator.__module__, 'Simulator' in dir(warpcloth))")
    assert out.split() == ["warpcloth.simulator", "True"]


#: Builds and steps a small sheet (warpcloth starts Warp and loads its kernel modules), then says
#: whether Warp's log level is warnings-only.
_STEP = (
    "import warp as wp\nfrom warpcloth.scenarios import sheet\n"
    "sim = sheet.build(rows=4, cols=4)\nsim.simulate(2)\nprint('warnings-only', wp.config.log_level == wp.LOG_WARNING)"
)


def test_warp_is_quiet_where_warpcloth_starts_it_unless_warpcloth_warp_verbose():
    # stdout carries results (--json): no banner, no "Module ... load on device" lines on it
    assert _python(_STEP).splitlines() == ["warnings-only True"]
    loud = _python(_STEP, WARPCLOTH_WARP_VERBOSE="1").splitlines()
    assert loud[-1] == "warnings-only False"
    assert any(line.startswith("Module warpcloth.kernels.") for line in loud), loud


def test_run_json_stdout_is_the_result_only():
    proc = subprocess.run(
        [sys.executable, "-m", "warpcloth", "run", "sheet", "--size", "6", "--num-frames", "2", "--json"],
        capture_output=True,
        text=True,
        timeout=300,
        env={k: v for k, v in os.environ.items() if k != "WARPCLOTH_WARP_VERBOSE"},
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert json.loads(proc.stdout)["integrator"] == "explicit_euler"
