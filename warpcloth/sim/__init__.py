"""What a step reads and writes. Imports only ``warpcloth.errors``, ``warpcloth.kernels`` and itself.

- ``model``: the cloth model (ClothModel, build_model, the default spring parameters);
  ``grid``: the Provot grid builder; ``mesh``: cloth from a triangle mesh; ``selection``: which
  vertices pins, groups and predicates name;
- ``state``; ``control``: gravity, drag, wind, pin tracks, colliders;
- ``tracks``: keyframed or rigid motion, the base of ``pins`` (kinematic pins) and of the pose
  tracks in ``colliders`` (the collider shapes); ``contacts``: the colliders on the device;
- ``coloring``: graph colourings; ``device``: the device rule."""
