"""A run above the stepping core: the harness (frames, timing, verdicts, :class:`RunResult`), the
metrics it reduces on the device, and the parameter table every front end is generated from.
Imports the layers below it; never ``warpcloth.io`` (files and the terminal are the caller's)."""
