"""Registered, and everything follows: an integrator registered at run time (a few lines, below) is
held to the whole contract (tests/test_contract.py) and reaches ``warpcloth study``, ``run``,
``sweep`` and ``--help`` with its own option and its own default for an option name pbd and xpbd
share, without any name-keyed table to extend. Everything runs in this process (a subprocess would
not see the registration), and the scheme is unregistered after each test."""

from __future__ import annotations

import csv
import json
from typing import ClassVar

import pytest
import test_contract as contract  # (a module attribute: pytest does not collect its tests twice)

from warpcloth import WarpclothError
from warpcloth.cli import main
from warpcloth.integrators import (
    ExplicitEuler,
    Integrator,
    Option,
    integrator_class,
    integrator_names,
    option_help,
    registered,
    unregister,
)
from warpcloth.lab.configs import configurations, static_configurations, study_options, work


class SubstepEuler(ExplicitEuler):
    """Symplectic Euler in ``substeps`` substeps of dt / substeps per step: declares nothing but its
    name and options, so the base class's defaults for the study and the contract apply."""

    name = "substep_euler"
    options = (
        Option("substeps", int, 2, "symplectic Euler substeps per step (>= 1)", check=lambda v: v < 1 and ">= 1"),
        Option(
            "substep_note", int, 0, "a number the scheme keeps and ignores (>= 0)", check=lambda v: v < 0 and ">= 0"
        ),
    )

    #: The options of every instance made (what ``run`` and ``sweep`` passed on).
    made: ClassVar[list] = []

    def __init__(self, **options):
        super().__init__(**options)
        SubstepEuler.made.append(self.option_values())

    def step(self, state, control, dt):
        for _ in range(self.substeps):
            super().step(state, control, dt / self.substeps)


@pytest.fixture
def scheme():
    with registered(SubstepEuler):
        yield SubstepEuler.name
    assert SubstepEuler.name not in integrator_names()


def test_registered_is_registered_for_the_block_only():
    assert SubstepEuler.name not in integrator_names()
    with registered(SubstepEuler) as cls:
        assert integrator_class("substep_euler") is cls and integrator_names()[-1] == "substep_euler"
        with pytest.raises(WarpclothError, match="already registered"):
            with registered(SubstepEuler):
                pass
    assert SubstepEuler.name not in integrator_names()
    with pytest.raises(WarpclothError, match="unknown integrator 'substep_euler'"):
        unregister("substep_euler")


def test_a_scheme_that_declares_nothing_gets_the_strict_defaults():
    """The contract's tolerance is 1e-3 unless a class loosens it itself; the study's grid is its
    default options at whole steps per frame; no option is fixed, and options do not change its cost."""
    assert SubstepEuler.free_motion_rtol == Integrator.free_motion_rtol == 1e-3
    assert SubstepEuler.free_fall == "euler" and SubstepEuler.explicit  # inherited from explicit_euler
    bare = type("Bare", (Integrator,), {"name": "bare"})
    assert not bare.explicit and bare.study_fixed_options == {} and bare.relative_work({}) == 1.0
    assert bare.study_grid["quick"] == ({}, (0.5, 1, 4))


# -- the contract, every check of tests/test_contract.py ---------------------------------------------
def test_contract_pins(scheme):
    contract.test_pins_do_not_move_by_one_bit(scheme)


def test_contract_hanging_mass(scheme):
    contract.test_hanging_mass_rests_at_its_schemes_extension(scheme)


def test_contract_rest(scheme):
    contract.test_rest_stays_at_rest(scheme)


def test_contract_graph_replay(scheme):
    contract.test_graph_replay_is_bit_identical_to_launches(scheme, "cpu")


@pytest.mark.parametrize("graph", [False, True], ids=["plain", "captured"])
def test_contract_no_allocation(scheme, graph, count_allocations):
    contract.test_step_allocates_no_memory(scheme, graph, count_allocations)


def test_contract_free_fall(scheme):
    contract.test_free_cloth_falls_along_its_plane_by_its_schemes_discrete_free_fall(scheme)


def test_contract_slope(scheme):
    contract.test_free_cloth_slides_down_a_frictionless_slope_at_g_sin(scheme, {})


def test_contract_momentum(scheme):
    contract.test_free_cloth_keeps_its_momentum(scheme)


def test_an_unknown_scheme_is_held_to_1e3():
    """A scheme whose free fall is 1 % short (its steps 0.5 % shorter than dt) fails the contract: a
    name the contract does not know is not let through at 2 %."""

    class Lagging(SubstepEuler):
        name = "lagging_euler"

        def step(self, state, control, dt):
            super().step(state, control, 0.995 * dt)

    with registered(Lagging):
        with pytest.raises(AssertionError, match="fell"):
            contract.test_free_cloth_falls_along_its_plane_by_its_schemes_discrete_free_fall("lagging_euler")


# -- the study, run, sweep and --help ---------------------------------------------------------------
def test_study_configurations_and_estimate(scheme, capsys, tmp_path, monkeypatch):
    cls = integrator_class(scheme)
    assert [c.k for c in configurations(scheme, 1e-3, "quick")] == [17, 34, 67]  # explicit: 1, 1/2, 1/4 of 1 ms
    assert [c.k for c in static_configurations(scheme, 1e-3)] == [17]
    assert study_options(scheme, {"substeps": 3}) == {"substeps": 3} and work(scheme, {"substeps": 8}) == 1.0
    assert cls.study_grid is ExplicitEuler.study_grid
    monkeypatch.chdir(tmp_path)
    argv = ["study", "--profile", "quick", "--integrators", scheme, "--sizes", "8", "--estimate", "--quiet"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "estimate of profile quick" in out and "total about" in out and scheme in out
    assert list(tmp_path.iterdir()) == []


def test_run_takes_its_options(scheme, capsys):
    argv = ["run", "sheet", "--integrator", scheme, "--size", "6", "--num-frames", "2", "--device", "cpu", "--json"]
    SubstepEuler.made.clear()
    assert main([*argv, "--substeps", "3", "--substep-note", "7"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["integrator"] == scheme and d["particles"] == 36 and d["stable"] and d["frames"] == 2
    assert SubstepEuler.made and SubstepEuler.made[-1] == {"substeps": 3, "substep_note": 7}
    # the scheme's own declaration checks the value (pbd's substeps check is another one)
    assert main([*argv, "--substeps", "0"]) == 2
    assert "substeps >= 1, got '0'" in capsys.readouterr().err
    assert main([*argv, "--pd-iterations", "3"]) == 2
    assert "does not apply to integrator 'substep_euler'" in capsys.readouterr().err


def test_sweep_runs_it(scheme, tmp_path):
    tests = tmp_path / "tests.xml"
    tests.write_text(
        '<test_list device="cpu">\n'
        f'  <test id="mine" integrator="{scheme}" size="6" duration="0.05" substeps="1 3" scenario="sheet"/>\n'
        "</test_list>\n"
    )
    out = tmp_path / "results.csv"
    assert main(["sweep", str(tests), "--out", str(out), "--quiet"]) == 0
    rows = list(csv.DictReader(out.open()))
    assert [r["integrator"] for r in rows] == [scheme, scheme]
    assert sorted(r["options"] for r in rows) == ["substeps=1", "substeps=3"]


def test_help_shows_its_option_and_each_owners_default(scheme, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["run", "--help"])
    assert exit_.value.code == 0
    text = " ".join(capsys.readouterr().out.split())  # argparse wraps the help
    assert "--substep-note INT a number the scheme keeps and ignores (>= 0) [substep_euler; default 0]" in text
    assert "[pbd: 4, xpbd: 4, substep_euler: 2]" in text
    assert option_help("iterations").endswith("[pbd, xpbd; default 10]")  # one declaration: one default
