"""Checkpoints: a run's state in a file, to continue a bake where it stopped.

A checkpoint is one NumPy ``.npz`` file, written atomically (:func:`~warpcloth.io.files.write_atomic`),
holding a :class:`~warpcloth.simulator.Snapshot`: every device array the run owns (positions,
velocities, the integrator's history and scratch, the self-contact lists, the device clock, the
tracks' state), the host clock, and a header (JSON) with the format's name and version, the
model's fingerprint (:func:`model_fingerprint`) and the run's setup. Loading it into a simulator of
another model, integrator, dt or self-collision setting is refused in one line; so is a damaged
or truncated file. ``warpcloth run ... --checkpoint FILE`` writes one (:class:`CheckpointWriter`,
a frame sink) and ``--resume-from FILE`` continues from one, bit-identically to an uninterrupted
run on the same device (docs/driving.md, "Checkpoints").
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from dataclasses import fields

import numpy as np
import warp as wp

from warpcloth.errors import WarpclothError, warn
from warpcloth.io.files import check_output_path, read_input, write_atomic
from warpcloth.simulator import Simulator, Snapshot

#: The header's ``format``; a file without it is not a warpcloth checkpoint.
FORMAT = "warpcloth-checkpoint"
#: The layout of the file; a checkpoint of another version is refused (its arrays may mean other things).
VERSION = 1
#: What a checkpoint's name must end with.
EXTENSIONS = (".npz",)
#: The largest checkpoint read [bytes] (a 256² cloth with self-collision is about 100 MB).
MAX_BYTES = 4 * 1024**3


def model_fingerprint(model) -> str:
    """SHA-256 (hex, 16 digits) of the model: its size and every array that defines it
    (rest positions, masses, pins, springs and their parameters, triangles, hinges), so that two
    builds of the same cloth agree and a cloth of any other size, material or pin set does not."""
    h = hashlib.sha256()
    h.update(f"{model.rows}x{model.cols}:{model.particle_count}".encode())
    for f in fields(model):
        value = getattr(model, f.name)
        if isinstance(value, wp.array):
            value = value.numpy()
        if isinstance(value, np.ndarray):
            h.update(f.name.encode())
            h.update(str(value.dtype).encode() + str(value.shape).encode())
            h.update(np.ascontiguousarray(value).tobytes())
    return h.hexdigest()[:16]


def check_checkpoint_path(path) -> str:
    """Check, before any work, that a checkpoint can be written at ``path`` (a ``.npz`` file)."""
    return check_output_path(path, "checkpoint", EXTENSIONS)


def checkpoint_bytes(sim: Simulator, run: dict | None = None) -> bytes:
    """The checkpoint of ``sim`` now, as the bytes of a ``.npz`` file (reads the device)."""
    snap = sim.snapshot(run)
    paths = sorted(snap.arrays)
    header = {
        "format": FORMAT,
        "version": VERSION,
        "model": model_fingerprint(sim.model),
        "particles": sim.model.particle_count,
        "setup": snap.setup,
        "clock": snap.clock,
        "run": snap.run,
        "arrays": [[p, snap.layout[p][0], list(snap.layout[p][1])] for p in paths],
    }
    out = io.BytesIO()
    contents = {"header": np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)}
    contents.update({f"a{k:04d}": snap.arrays[p] for k, p in enumerate(paths)})
    np.savez_compressed(out, **contents)
    return out.getvalue()


def save_checkpoint(path, sim: Simulator, run: dict | None = None) -> str:
    """Write the checkpoint of ``sim`` to ``path`` atomically (the old file stays whole until the
    new one is); returns ``path``."""
    check_checkpoint_path(path)
    return write_atomic(path, checkpoint_bytes(sim, run), what="checkpoint")


def load_checkpoint(path, sim: Simulator | None = None) -> Snapshot:
    """The :class:`~warpcloth.simulator.Snapshot` in the checkpoint ``path``, checked against
    ``sim``'s model where given (restore it with :meth:`Simulator.restore
    <warpcloth.simulator.Simulator.restore>`, which checks the setup). Raises a
    :class:`~warpcloth.errors.WarpclothError` of one line for a file that is not a checkpoint,
    is damaged or truncated, of another version, or of another model."""
    data = read_input(path, "checkpoint", MAX_BYTES)
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            header = json.loads(bytes(npz["header"]).decode())
            if not isinstance(header, dict) or header.get("format") != FORMAT:
                raise ValueError("its header is not a warpcloth checkpoint's")
            if header.get("version") != VERSION:
                raise WarpclothError(
                    f"checkpoint {path} is of format version {header.get('version')!r}; this warpcloth reads "
                    f"version {VERSION}: write it again with this version"
                )
            entries = header["arrays"]
            arrays = {
                p: np.asarray(npz[f"a{k:04d}"], dtype=np.uint8).reshape(-1) for k, (p, _, _) in enumerate(entries)
            }
            layout = {p: (str(dtype), tuple(int(n) for n in shape)) for p, dtype, shape in entries}
            snap = Snapshot(arrays, layout, dict(header["clock"]), dict(header["setup"]), dict(header.get("run", {})))
            fingerprint = str(header["model"])
    except WarpclothError:
        raise
    except (ValueError, KeyError, TypeError, OSError, EOFError, zipfile.BadZipFile, UnicodeDecodeError) as exc:
        raise WarpclothError(
            f"checkpoint {path} is damaged or not a warpcloth checkpoint ({type(exc).__name__}: {str(exc)[:80]})"
        ) from None
    if sim is not None and fingerprint != model_fingerprint(sim.model):
        raise WarpclothError(
            f"checkpoint {path} is of another model (fingerprint {fingerprint}, this run's "
            f"{model_fingerprint(sim.model)}): resume with the scenario and flags that wrote it"
        )
    return snap


def resume_checkpoint(path, sim: Simulator) -> Snapshot:
    """Load the checkpoint ``path`` into ``sim`` (checked: model, then setup); returns its snapshot."""
    snap = load_checkpoint(path, sim)
    try:
        sim.restore(snap)
    except WarpclothError as exc:
        raise WarpclothError(f"checkpoint {path} does not fit this run: {exc}") from None
    return snap


class CheckpointWriter:
    """A frame sink that writes the run's checkpoint to ``path``: at its end (:meth:`close`), and
    with ``every`` = K also after every K-th frame (the file then always holds the latest, even
    where the run is killed later). It reads the simulator, not the frames it is handed.

    A run that went unstable gets no checkpoint at its end (the state is not worth continuing):
    one line on stderr says so, and the file written after the last K-th frame, if any, stays."""

    def __init__(self, path, sim: Simulator, every: int | None = None):
        self.path = check_checkpoint_path(path)
        if every is not None and (isinstance(every, bool) or not isinstance(every, int) or every < 1):
            raise WarpclothError(f"checkpoint every: must be a whole number of frames >= 1, got {every!r}")
        self.sim, self.every = sim, every
        self.frames = 0  # frames received (the first is the run's start)
        self._steps_at_last_frame = None
        self.written = 0

    def write_frame(self, points, sim_time=None) -> None:
        self._steps_at_last_frame = self.sim.steps
        if self.every is not None and self.frames and self.frames % self.every == 0:
            save_checkpoint(self.path, self.sim, {"frame": self.frames})
            self.written += 1
        self.frames += 1

    def close(self) -> str | None:
        if self._steps_at_last_frame is not None and self.sim.steps != self._steps_at_last_frame:
            warn(
                f"checkpoint {self.path} not written at the run's end: the run went unstable after step "
                f"{self._steps_at_last_frame}"
            )
            return None
        save_checkpoint(self.path, self.sim, {"frame": max(0, self.frames - 1)})
        self.written += 1
        return self.path

    def abort(self) -> None:
        """Nothing to undo: a checkpoint is written whole or not at all (at close, or every K frames)."""


__all__ = [
    "EXTENSIONS",
    "FORMAT",
    "VERSION",
    "CheckpointWriter",
    "check_checkpoint_path",
    "checkpoint_bytes",
    "load_checkpoint",
    "model_fingerprint",
    "resume_checkpoint",
    "save_checkpoint",
]
