"""What a step reads and writes: the cloth model and its builders (grid, triangle mesh), vertex
selection, the state, the control (gravity, drag, wind, pin tracks, colliders), colliders and
their device-side contact set, kinematic pins, colourings, the device. Imports only
``warpcloth.errors``, ``warpcloth.kernels`` and itself."""
