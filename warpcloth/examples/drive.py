"""Drive a cloth from your own frame loop (docs/driving.md): a hand drags the corner of a hanging
sheet and a ball is pushed into it, both set from the host each frame; the captured frame graph
is replayed every frame.

    python -m warpcloth.examples.drive [--device cpu] [--num-frames 120] [--size 32] [--usd drive.usda]
"""

import argparse

import numpy as np
import warp as wp

from warpcloth.io.usd import UsdWriter
from warpcloth.sim.colliders import ColliderTrack, Sphere
from warpcloth.sim.control import Control
from warpcloth.sim.device import init_warp
from warpcloth.sim.grid import build_grid_cloth
from warpcloth.sim.pins import PinTrack
from warpcloth.simulator import Simulator


class Example:
    """The loop of docs/driving.md: ``step()`` moves the hand and the ball and simulates a frame."""

    def __init__(self, size: int = 32, stage_path: str | None = None, frame_dt: float = 1.0 / 60.0):
        corner, other = 0, size - 1  # the top corners of the hanging sheet
        self.model = build_grid_cloth(size, size, pins=[corner, other])
        self.hand = PinTrack.driven([corner], name="hand")
        ball = Sphere(center=(0.5, -0.6, -0.3), radius=0.15, friction=0.3, track=ColliderTrack.driven())
        self.control = Control(pin_tracks=(self.hand,), colliders=(ball,))
        self.sim = Simulator(self.model, "xpbd", self.control)
        self.steps = max(1, round(frame_dt / self.sim.dt))
        self.grip = self.model.host.q[corner].astype(np.float64)
        self.frame = 0
        self.usd = None
        if stage_path:
            self.usd = UsdWriter(stage_path, self.model, fps=1.0 / frame_dt, colliders=self.control.colliders)

    def step(self) -> None:
        t = (self.frame + 1) * self.steps * self.sim.dt  # the time at the end of this frame
        self.sim.set_pin_targets([self.grip + [0.3 * np.sin(2 * t), 0.1 * t, 0.2 * t]])  # drag the corner
        self.sim.set_collider_pose(0, offset=(0.0, 0.0, 0.4 * t))  # push the ball into the cloth
        self.sim.simulate(self.steps)
        self.frame += 1

    def render(self) -> None:
        if self.usd is not None:
            self.usd.write_frame(self.sim.state.particle_q.numpy(), self.sim.sim_time)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default=None, help="Warp device (default: Warp's)")
    parser.add_argument("--num-frames", type=int, default=120)
    parser.add_argument("--size", type=int, default=32)
    parser.add_argument("--usd", dest="stage_path", default=None, help="write the frames to this USD file")
    args = parser.parse_args(argv)
    init_warp()  # without Warp's start-up lines (e.g. "CUDA driver not found") on stderr
    with wp.ScopedDevice(args.device):
        example = Example(args.size, args.stage_path)
        for _ in range(args.num_frames):
            example.step()
            example.render()
        corner = example.sim.state.particle_q.numpy()[0]
        print(
            f"{args.num_frames} frames of {example.steps} steps; the corner is at {np.round(corner, 3).tolist()}, "
            f"graph replay: {example.sim.graph_enabled}"
        )
        if example.usd is not None:
            print(f"wrote {example.usd.close()}")


if __name__ == "__main__":
    main()
