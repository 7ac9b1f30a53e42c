"""The character scene (docs/character.md): the mannequin's skinning (rest pose = bind pose, rigid
parts rigid, continuous motion, keyframes = poses) and the scene at a reduced size: no cloth
triangle crossed by the body's edges nor by another, no cloth vertex inside the body, the pins on the
band (the skin moved out) at every frame."""

import numpy as np
import pytest

from warpcloth.errors import WarpclothError
from warpcloth.io.usd import UsdWriter
from warpcloth.lab.intersections import check_frames, check_usd, mesh_segments
from warpcloth.scenarios import character as ch
from warpcloth.scenarios import get_scenario
from warpcloth.sim.builder import ClothBuilder
from warpcloth.sim.colliders import MeshCollider, MeshTrack, closest_surface_points
from warpcloth.sim.mannequin import BONES, CAPSULES, EASE_IN, Mannequin, capsule_mesh


@pytest.fixture(scope="module")
def body():
    return Mannequin.build()


def test_capsule_mesh_is_closed_and_wound_outward():
    v, t, s = capsule_mesh((0.0, 0.0, 0.0), (0.0, 0.4, 0.0), 0.1, segments=12, rings=4)
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert (counts == 2).all()  # closed: every edge in two triangles
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    volume = np.einsum("ij,ij->i", np.cross(a, b), c).sum() / 6.0
    exact = np.pi * 0.1**2 * 0.4 + 4.0 / 3.0 * np.pi * 0.1**3
    assert 0.9 * exact < volume < exact  # positive: outward; inscribed facets: a little less
    radial = np.linalg.norm(v[:, [0, 2]], axis=1)
    assert np.isclose(radial[(s > 0) & (s < 0.4)], 0.1).all()  # the cylinder's rings on the radius
    assert s.min() == pytest.approx(-0.1) and s.max() == pytest.approx(0.5)


def test_rest_pose_is_the_bind_pose_and_weights_are_a_partition(body, tmp_path):
    assert np.allclose(body.weights.sum(axis=1), 1.0) and (body.weights >= 0).all()
    assert np.abs(body.pose(0.0) - body.vertices).max() < 1e-14  # sum_b w_b x = x up to rounding
    assert np.abs(body.pose(-1.0) - body.vertices).max() < 1e-14
    assert body.weights.shape == (len(body.vertices), len(BONES))
    assert body.vertices[:, 1].min() > 0.0 and 1.7 < body.vertices[:, 1].max() < 1.8  # feet above 0, 1.75 m tall


def test_rigid_parts_move_rigidly_and_limbs_bend(body):
    x = body.pose(1.7)
    starts = np.cumsum([0] + [len(capsule_mesh(a, b, r)[0]) for _, a, b, r in CAPSULES])
    head = slice(starts[4], starts[5])  # the head capsule: all on the head bone
    d0 = np.linalg.norm(body.vertices[head][:, None] - body.vertices[head][None], axis=2)
    d1 = np.linalg.norm(x[head][:, None] - x[head][None], axis=2)
    assert np.allclose(d0, d1, atol=1e-12)
    thigh = slice(starts[5], starts[6])
    assert np.abs(x[thigh] - body.vertices[thigh]).max() > 0.05  # a thigh lifted


def test_motion_is_continuous_and_eased_in(body):
    times = np.arange(0.0, 4.0, 1.0 / 600.0)
    poses = np.stack([body.pose(t) for t in times[::10]])
    speed = np.linalg.norm(np.diff(poses, axis=0), axis=2).max(axis=1) * 60.0  # m/s over 1/60 s
    assert speed.max() < 2.0  # no jump: a limb at most walking speed
    fine = np.linalg.norm(body.pose(2.0 + 1e-4) - body.pose(2.0), axis=1).max()
    assert fine < 2.0 * 1e-4  # continuous at a small step too
    assert speed[0] < 0.05 * speed.max()  # eased in from rest: the first 1/60 s barely moves
    assert speed[round(EASE_IN * 60) :].mean() > 0.3  # then it moves


def test_track_keys_are_the_poses(body):
    track = body.track(0.5, fps=20.0)
    assert track.times[0] == 0.0 and track.times[-1] >= 0.5
    for k in (0, 3, len(track.times) - 1):
        assert np.allclose(track.points[k], body.pose(track.times[k]))
    band = body.offset(0.02)
    assert np.allclose(np.linalg.norm(band - body.vertices, axis=1), 0.02)


def test_character_is_registered():
    assert get_scenario("character") is ch.SCENARIO
    assert ch.SCENARIO.defaults.integrator == "xpbd"


def test_character_scene_small_has_no_intersection_and_pins_follow_the_body(body):
    """6 x 6 cape and a 6 x 12 skirt, 0.5 s (the ease-in: the body turns, the legs start lifting)."""
    sim = ch.build(rows=6, cols=6, duration=0.5, device="cpu")
    model = sim.model
    assert [p.name for p in model.pieces] == ["cape", "skirt"]
    collider = sim.control.colliders[0]
    tracks = sim.control.pin_tracks
    band = body.offset(ch.BAND)
    steps = max(1, round(1.0 / 60.0 / sim.dt))
    frames, times = [], []
    for _ in range(30):
        sim.simulate(steps)
        x = sim.state.particle_q.numpy().astype(np.float64)
        frames.append(x)
        times.append(sim.sim_time)
        for track in tracks:  # the pins on the band's triangles at this time
            tied = np.einsum("pj,pjc->pc", track.weights, body.pose(sim.sim_time, band)[body.triangles[track.faces]])
            assert np.abs(x[list(track.particles)] - tied).max() < 2e-4
    tris = model.host.tris
    report = check_frames(
        frames, tris, times, lambda k: mesh_segments(collider.at(times[k]).vertices, collider.triangles)
    )
    assert report.clean, report.summary()
    posed = collider.at(times[-1]).vertices
    faces, weights = closest_surface_points(posed, body.triangles, frames[-1])
    q = np.einsum("pj,pjc->pc", weights, posed[body.triangles[faces]])
    a, b, c = (posed[body.triangles[faces][:, k]] for k in range(3))
    outward = np.einsum("ij,ij->i", np.cross(b - a, c - a), frames[-1] - q)
    assert (outward > 0).all()  # every cloth vertex outside the body
    moved = np.linalg.norm(frames[-1][list(tracks[1].particles)] - model.host.q[list(tracks[1].particles)], axis=1)
    assert moved.max() > 0.01  # the waist turned with the body


def test_garments_without_a_material_or_of_another_size_are_refused():
    with pytest.raises(WarpclothError, match="made of materials.*not none"):
        ch.build(material="none", rows=6, cols=6, duration=0.1, device="cpu")
    with pytest.raises(WarpclothError, match="rows must be"):
        ch.build(rows=2, cols=6, duration=0.1, device="cpu")
    with pytest.raises(WarpclothError, match="--width and --height do not apply"):
        ch.build(rows=6, cols=6, width=2.0, duration=0.1, device="cpu")


def test_check_usd_reads_pieces_as_one_cloth_and_a_deforming_collider_per_frame(tmp_path):
    """check-intersections on what the character writes: /World/Cloth/<piece> meshes (one cloth: the
    pieces against each other too) and a deforming mesh collider's points at each frame."""
    b = ClothBuilder()
    b.add_grid(3, 3, 1.0, 1.0, total_mass=0.1, plane="horizontal", name="a")
    b.add_grid(3, 3, 1.0, 1.0, total_mass=0.1, plane="horizontal", origin=(0.0, 0.5, 0.0), name="b")
    model = b.finalize("cpu")
    q = model.host.q.astype(np.float64)
    quad = np.array([[0.2, -1.0, 0.25], [0.8, -1.0, 0.25], [0.8, -0.5, 0.25], [0.2, -0.5, 0.25]])
    keys = np.stack([quad, quad + [0.0, 0.75, 0.0], quad])  # frame 1: its edges through piece a (y = 0)
    wall = MeshCollider(vertices=quad, triangles=[[0, 1, 2], [0, 2, 3]], track=MeshTrack.keyframes([0, 1, 2], keys))
    crossed = q.copy()
    a_points = q[:9] - q[:9].min(axis=0)  # piece b turned upright through piece a's middle (frame 2)
    crossed[9:] = np.stack([a_points[:, 0], a_points[:, 2] - 0.5, np.full(9, 0.5)], axis=1)
    path = str(tmp_path / "pieces.usda")
    with UsdWriter(path, model, fps=1.0, colliders=(wall,)) as usd:
        for k, x in enumerate((q, q, crossed)):
            usd.write_frame(x, float(k))
    report = check_usd(path)
    assert report.frames == 3
    assert report.collider_crossings[0] == 0 and report.collider_crossings[1] > 0 and report.collider_crossings[2] == 0
    assert report.self_intersections[:2] == [0, 0] and report.self_intersections[2] > 0
