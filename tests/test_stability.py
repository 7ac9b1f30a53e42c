"""What "unstable" means: non-finite state, strain past the instability strain, or energy that
grows without bound; and the default dt of a scheme from its stability region."""

import math

import pytest
from helpers import displace, single_spring

from warpcloth import Control, Simulator, WarpclothError
from warpcloth.cli import main
from warpcloth.integrators.base import runge_kutta_stable_dt
from warpcloth.integrators.midpoint import rk2_amplification
from warpcloth.lab.maxdt import find_max_dt, format_result
from warpcloth.run.harness import RunHarness
from warpcloth.run.metrics import DEFAULT_INSTABILITY_STRAIN
from warpcloth.scenarios import get_scenario, sheet

NO_GRAVITY = (0.0, 0.0, 0.0)
KS, MASS = 40.0, 0.1
OMEGA = math.sqrt(KS / MASS)  # 20 rad/s: the single spring's angular frequency


def spring_run(integrator, h_omega, duration, kd=0.0):
    sim = Simulator(
        single_spring(ks=KS, mass=MASS, kd=kd),
        integrator,
        Control(gravity=NO_GRAVITY, device="cpu"),
        dt=h_omega / OMEGA,
    )
    displace(sim, 1, (0.0, -0.05, 0.0))
    return sim, RunHarness(sim).run(duration, warm_up=False)


def test_undamped_midpoint_is_flagged_within_two_seconds():
    # RK2 amplifies the undamped spring by sqrt(1 + 0.4^4/4) per step: its energy grows without
    # bound, while the strain stays far below any strain limit for the first seconds
    _sim, r = spring_run("midpoint", 0.4, 2.0)
    assert not r.stable
    assert r.unstable_reason.startswith("energy growing without bound")
    assert r.unstable_time <= 2.0
    assert r.max_strain < 0.5  # the old criterion (strain, non-finite) could not see it


@pytest.mark.parametrize(
    "integrator,h_omega", [("explicit_euler", 1.9), ("verlet", 1.9), ("rk4", 2.7), ("midpoint", 0.4)]
)
def test_bounded_energy_errors_are_not_instability(integrator, h_omega):
    # symplectic Euler and Verlet below h omega = 2, RK4 below 2 sqrt 2: their energy error is
    # bounded (it oscillates); midpoint with a little damping (zeta = 0.05) decays
    kd = 2 * 0.05 * math.sqrt(KS * MASS) if integrator == "midpoint" else 0.0
    _, r = spring_run(integrator, h_omega, 6.0, kd=kd)
    assert r.stable, r.unstable_reason


def test_explicit_euler_above_its_limit_is_unstable():
    _, r = spring_run("explicit_euler", 2.1, 6.0)
    assert not r.stable


def test_rk2_stability_region_and_default_dt():
    undamped = single_spring(ks=KS, mass=MASS)
    assert runge_kutta_stable_dt(rk2_amplification, undamped, 0.0) == 0.0
    assert runge_kutta_stable_dt(rk2_amplification, undamped, 1.0) > 0.0  # drag damps every mode
    rk4 = runge_kutta_stable_dt(lambda z: 1 + z + z * z / 2 + z**3 / 6 + z**4 / 24, undamped, 0.0)
    omega_max = math.sqrt(2 * KS / MASS)  # Gershgorin bound of the pinned spring
    assert rk4 * omega_max == pytest.approx(2 * math.sqrt(2), rel=1e-3)  # RK4's imaginary-axis limit
    with pytest.raises(WarpclothError, match="midpoint .RK2. has no stable time step"):
        Simulator(undamped, "midpoint", Control(gravity=NO_GRAVITY, device="cpu"))


def test_midpoint_default_is_stable_without_spring_damping():
    # the old default (0.5 x the symplectic-Euler estimate) went unstable at 0.13 s here
    sim = sheet.build(integrator="midpoint", damping=0.0, rows=16, cols=16)
    r = RunHarness(sim).run(0.4)
    assert r.stable, r.unstable_reason


def test_midpoint_without_any_damping_is_one_line_before_running(capsys):
    assert (
        main(
            ["run", "sheet", "--integrator", "midpoint", "--damping", "0", "--drag", "0", "--rows", "6", "--cols", "6"]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len([l for l in err if "error" in l]) == 1 and "no stable time step" in err[-1]


def test_max_dt_of_undamped_midpoint_reports_no_stable_dt():
    scenario = get_scenario("sheet")
    cfg = scenario.config(integrator="midpoint", rows=6, cols=6, damping=0.0, drag=0.0)
    r = find_max_dt(scenario, cfg, duration=0.5)
    assert r.dt is None and r.no_stable_reason and r.trials == []
    assert "no stable dt exists" in format_result(r)


def test_instability_strain_default_option_and_max_dt_strain(capsys):
    assert DEFAULT_INSTABILITY_STRAIN == 0.5
    cfg = get_scenario("sheet").config(rows=6, cols=6, instability_strain=0.001)
    r = get_scenario("sheet").harness(cfg).run(0.2)
    assert not r.stable and "beyond the limit 0.001" in r.unstable_reason and r.instability_strain == 0.001
    assert (
        main(
            [
                "run",
                "sheet",
                "--rows",
                "6",
                "--cols",
                "6",
                "--duration",
                "0.2",
                "--instability-strain",
                "0.001",
                "--json",
            ]
        )
        == 0
    )
    assert '"stable": false' in capsys.readouterr().out
    scenario = get_scenario("sheet")
    m = find_max_dt(scenario, scenario.config(rows=6, cols=6, stiffness=(1e4, 1e3, 200)), duration=0.3, precision=0.1)
    stable_at_dt = [t for t in m.trials if t.dt == m.dt]
    assert m.max_strain == stable_at_dt[0].max_strain > 0.0
    assert "max strain" in format_result(m)
