"""The sink contract, over every output of ``warpcloth run`` (warpcloth.cli.run.OUTPUTS): a run that
aborts leaves the target exactly as it was (absent, or an older output's bytes and inode untouched),
close() returns the written path, and no temporary is left beside the target either way. The table
drives the flags and the summary, so a new entry is covered here and reported without more code."""

import os
from pathlib import Path

import numpy as np
import pytest

from warpcloth.cli import build_parser, main
from warpcloth.cli.model import config_from_args
from warpcloth.cli.run import OUTPUTS, OutputRun, output_writers
from warpcloth.io.files import TEMP_PREFIX
from warpcloth.io.meshio import read_obj
from warpcloth.scenarios import get_scenario

ARGS = ["--rows", "4", "--cols", "5", "--num-frames", "3"]


def parse(*argv):
    args = build_parser(("run",)).parse_args(["run", "sheet", *ARGS, *argv])
    args.argv = ["run", "sheet", *ARGS, *argv]
    return args


def temporaries(folder) -> list[str]:
    """Every temporary under ``folder`` (inside folder outputs too)."""
    return sorted(
        os.path.join(root, n)
        for root, dirs, names in os.walk(folder)
        for n in dirs + names
        if n.startswith(TEMP_PREFIX)
    )


def state(path):
    """What a target is: None (absent), (inode, bytes) of a file, or (inode, {name: (inode, bytes)}) of a folder."""
    p = Path(path)
    if not os.path.lexists(p):
        return None
    if p.is_dir():
        return p.stat().st_ino, {c.name: (c.stat().st_ino, c.read_bytes()) for c in sorted(p.iterdir())}
    return p.stat().st_ino, p.read_bytes()


class Boom:
    """A sink that fails at its second frame: the run aborts in the middle of its work."""

    def __init__(self):
        self.frames = 0

    def write_frame(self, points, sim_time=None):
        self.frames += 1
        if self.frames == 2:
            raise RuntimeError("boom")

    def close(self):
        return None

    def abort(self):
        pass


def frames_of(sim, count=3):
    """``count`` distinct finite frames of ``sim``'s cloth (its rest positions, lowered a little each frame)."""
    q = sim.state.particle_q.numpy().astype(np.float64)
    return [q - np.array([0.0, 0.01 * k, 0.0]) for k in range(count)]


@pytest.mark.parametrize("output", OUTPUTS, ids=lambda o: o.dest)
def test_the_flags_come_from_the_table(output):
    for flag in output.flags:
        args = parse(flag, output.sample)
        assert getattr(args, output.dest) == output.sample
    assert getattr(parse(), output.dest) is None
    assert len({o.dest for o in OUTPUTS}) == len(OUTPUTS)


@pytest.mark.parametrize("older", [False, True], ids=["absent", "older"])
@pytest.mark.parametrize("output", OUTPUTS, ids=lambda o: o.dest)
def test_a_run_that_aborts_leaves_the_target_as_it_was(tmp_path, capsys, output, older):
    target = str(tmp_path / output.sample)
    if older:  # a previous run's output, written the ordinary way
        assert main(["run", "sheet", *ARGS, output.flags[0], target, "-q"]) == 0
        assert os.path.exists(target)
    before, listing = state(target), sorted(os.listdir(tmp_path))
    args = parse(output.flags[0], target)
    scenario = get_scenario("sheet")
    writers = output_writers("sheet", args)
    assert len(writers) == 1
    with pytest.raises(RuntimeError, match="boom"):
        scenario.run(config_from_args(scenario, args), writers=[*writers, lambda sim, cfg: Boom()])
    assert state(target) == before
    assert sorted(os.listdir(tmp_path)) == listing
    assert temporaries(tmp_path) == []


@pytest.mark.parametrize("output", OUTPUTS, ids=lambda o: o.dest)
def test_close_returns_the_written_path_and_leaves_no_temporary(tmp_path, output):
    target = str(tmp_path / output.sample)
    args = parse(output.flags[0], target)
    scenario = get_scenario("sheet")
    cfg = config_from_args(scenario, args)
    sim = scenario.build(cfg)
    written = []
    for k in range(2):  # a new target, then an older one replaced
        output.check(target)
        sink = output.sink(target, OutputRun("sheet", args), sim, cfg)
        for t, points in enumerate(frames_of(sim, 2 + k)):
            sink.write_frame(points, t / cfg.fps)
        assert sink.close() == target
        assert temporaries(tmp_path) == []
        assert sorted(os.listdir(tmp_path)) == [output.sample]
        written.append(state(target))
    assert written[0][1] != written[1][1]  # the second run's frames, not the first's


def test_every_reported_output_is_in_the_summary(tmp_path, capsys):
    paths = {o.dest: str(tmp_path / o.sample) for o in OUTPUTS}
    argv = [a for o in OUTPUTS for a in (o.flags[0], paths[o.dest])]
    assert main(["run", "sheet", *ARGS, *argv]) == 0
    out = capsys.readouterr().out
    for o in OUTPUTS:
        path = paths[o.dest]
        size = sum(f.stat().st_size for f in Path(path).iterdir()) if os.path.isdir(path) else os.path.getsize(path)
        assert (f"  wrote {path} ({size:,} bytes, 4 frames)" in out) == o.report, out
    assert temporaries(tmp_path) == []


# -- the OBJ sequence ---------------------------------------------------------------------------


def test_obj_sequence_holds_one_obj_per_frame(tmp_path):
    target = tmp_path / "seq"
    args = parse("--obj-sequence", str(target))
    scenario = get_scenario("sheet")
    cfg = config_from_args(scenario, args)
    sim = scenario.build(cfg)
    (o,) = [o for o in OUTPUTS if o.dest == "obj_sequence"]
    sink = o.sink(str(target), OutputRun("sheet", args), sim, cfg)
    frames = frames_of(sim, 3)
    for t, points in enumerate([*frames, np.full_like(frames[0], np.nan)]):  # an unstable last frame: skipped
        sink.write_frame(points, t / cfg.fps)
    sink.close()
    assert sorted(p.name for p in target.iterdir()) == ["frame_0000.obj", "frame_0001.obj", "frame_0002.obj"]
    tris = np.asarray(sim.model.host.tris)
    for k, points in enumerate(frames):
        mesh = read_obj(str(target / f"frame_{k:04d}.obj"))
        np.testing.assert_allclose(mesh.vertices, points, rtol=1e-8, atol=1e-12)
        assert np.array_equal(np.sort(mesh.triangles, axis=1), np.sort(tris, axis=1))


def test_obj_sequence_refuses_a_link_and_a_folder_of_other_files(tmp_path, capsys):
    mine = tmp_path / "notes"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    link = tmp_path / "link"
    link.symlink_to(tmp_path / "elsewhere")
    file = tmp_path / "file.obj"
    file.write_text("x")
    for path, why in [
        (mine, "is a folder holding other files ('notes.txt')"),
        (link, "is a link"),
        (file, "exists and is not a folder"),
        (tmp_path / "no" / "seq", "does not exist"),
    ]:
        assert main(["run", "sheet", *ARGS, "--obj-sequence", str(path)]) == 2
        (line,) = capsys.readouterr().err.splitlines()
        assert line.startswith(f"warpcloth: error: OBJ sequence path {str(path)!r}") and why in line, line
    assert (mine / "notes.txt").read_text() == "mine" and not (tmp_path / "elsewhere").exists()
    assert temporaries(tmp_path) == []
