"""The previews draw the colliders (each kind's triangles lie on its surface, posed at the frame's
time) and the HTML player starts from the side the cloth faces (a hanging flag face-on, not
edge-on; #view=YAW,PITCH overrides it)."""

import numpy as np
import pytest

from warpcloth import Box, Capsule, Plane, Sphere
from warpcloth.io.player import default_view
from warpcloth.io.preview import collider_triangles
from warpcloth.sim.colliders import signed_distance
from warpcloth.sim.grid import build_grid_cloth

LO, HI = np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0])


@pytest.mark.parametrize(
    "collider",
    [
        Sphere(center=(0.1, 0.2, 0.3), radius=0.4),
        Capsule(a=(-0.5, 0, 0), b=(0.5, 0.2, 0.1), radius=0.2),
        Box(center=(0, 0.5, 0), half_extents=(0.3, 0.2, 0.1), rotation=(0, 0.3826834, 0, 0.9238795)),
        Plane(point=(0, -0.2, 0), normal=(0, 1, 0.2)),
    ],
)
def test_preview_triangles_lie_on_the_collider(collider):
    tri = collider_triangles(collider, LO, HI)
    assert tri.shape[1:] == (3, 3) and len(tri) >= 2
    assert np.allclose(signed_distance(collider, tri.reshape(-1, 3)), 0.0, atol=1e-9)
    if collider.kind == "plane":  # a square across the plot's cube (a tilted one a little past it), not 10 x it
        assert np.abs(tri.reshape(-1, 3)).max() <= 1.1


def test_cli_preview_draws_the_colliders(tmp_path, capsys):
    # the same drape with and without its colliders drawn: the pictures differ where they are
    pytest.importorskip("matplotlib")
    from warpcloth.cli import main
    from warpcloth.io.preview import PreviewWriter

    assert main(["run", "drape", "--size", "6", "--num-frames", "2", "--preview", str(tmp_path / "d.png"), "-q"]) == 0
    assert (tmp_path / "d.png").stat().st_size > 0
    model = build_grid_cloth(6, 6, device="cpu")
    pictures = []
    for colliders in ((), (Sphere(center=(0.5, -0.5, 0), radius=0.3),)):
        w = PreviewWriter(str(tmp_path / f"p{len(colliders)}.png"), model, colliders=colliders)
        w.write_frame(model.host.q, 0.0)
        pictures.append((tmp_path / f"p{len(colliders)}.png").read_bytes() if w.close() else None)
    assert pictures[0] != pictures[1]


def test_the_player_faces_a_hanging_flag():
    # the flag hangs in the x-y plane (normal along z): the camera's eye direction
    # (cos p sin y, sin p, cos p cos y) is within 0.4 rad of the normal, not at 90 degrees to it
    model = build_grid_cloth(10, 12, device="cpu")
    view = default_view(model.host.q, model.host.tris)
    eye = np.array(
        [
            np.cos(view["pitch"]) * np.sin(view["yaw"]),
            np.sin(view["pitch"]),
            np.cos(view["pitch"]) * np.cos(view["yaw"]),
        ]
    )
    p, t = model.host.q.astype(np.float64), model.host.tris
    n = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]).sum(axis=0)
    assert abs(eye @ n / np.linalg.norm(n)) > 0.85
    flat = p[:, [0, 2, 1]]  # the same cloth lying horizontally: seen from above
    assert default_view(flat, t) == {"yaw": 0.55, "pitch": 0.6}
