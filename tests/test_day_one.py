"""Day-one inputs: a cloth that starts inside a collider gets one warning line before the run
(how many vertices, which collider), and an unstable run's summary always says why."""

import numpy as np

from warpcloth import Box, Capsule, Plane, Sphere
from warpcloth.cli import main
from warpcloth.sim.colliders import signed_distance
from warpcloth.sim.contacts import starting_inside


def test_host_signed_distances_are_exact():
    x = np.array([[0.0, 0.0, 0.0], [0.0, 2.0, 0.0], [3.0, 0.0, 0.0]])
    assert np.allclose(signed_distance(Sphere(center=(0, 0, 0), radius=1.0), x), [-1.0, 1.0, 2.0])
    assert np.allclose(signed_distance(Plane(point=(0, 1, 0)), x), [-1.0, 1.0, -1.0])
    assert np.allclose(signed_distance(Capsule(a=(-1, 0, 0), b=(1, 0, 0), radius=0.5), x), [-0.5, 1.5, 1.5])
    # a box turned 90 degrees about z: its long x side now lies along y
    box = Box(center=(0, 0, 0), half_extents=(2.0, 0.5, 0.5), rotation=(0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)))
    assert np.allclose(signed_distance(box, x), [-0.5, -0.0, 2.5], atol=1e-12)


def test_vertices_inside_are_counted_per_collider():
    points = np.array([[0.0, 0.1, 0.0], [0.0, 0.5, 0.0], [5.0, 0.5, 0.0], [0.0, -0.1, 0.0]])
    free = np.array([True, True, True, False])  # the pinned one is not counted
    found = starting_inside((Plane(), Sphere(center=(0, 0, 0), radius=0.3)), points, free)
    assert [(k, n) for k, _, n in found] == [(1, 1)] and "sphere at (0, 0, 0), radius 0.3" in found[0][1]


def test_a_cloth_started_inside_a_sphere_is_warned_before_the_run_and_its_failure_explained(capsys):
    # the drape's cloth (y = 0.75) inside a sphere of radius 0.5 at y = 0.4; a low instability
    # strain makes the push-out an instability: the summary names the collider as the cause
    code = main(
        [
            "run",
            "drape",
            "--size",
            "8",
            "--num-frames",
            "5",
            "--collider",
            "sphere:center=0/0.4/0,radius=0.5",
            "--instability-strain",
            "0.01",
        ]
    )
    out, err = capsys.readouterr()
    assert code == 0
    warning = [line for line in err.splitlines() if "start inside" in line]
    assert len(warning) == 1 and warning[0].startswith("warpcloth: warning: ")
    assert "of 64 free cloth vertices start inside collider 2 (sphere at (0, 0.4, 0), radius 0.5)" in warning[0]
    assert "stable: NO (" in out and "started inside collider 2 (sphere" in out


def test_an_unstable_run_without_colliders_names_the_time_step(capsys):
    code = main(["run", "sheet", "--size", "8", "--num-frames", "5", "--dt", "0.01"])
    out, err = capsys.readouterr()
    assert code == 0 and "stable: NO (" in out and "start inside" not in err
    assert "the likeliest cause is the time step: dt = 0.01 s for explicit_euler" in out and "warpcloth max-dt" in out
