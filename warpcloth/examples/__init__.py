"""The shipped examples (``warpcloth.examples`` once installed): the XML test lists, the cape mesh
and its scenario file, and example scripts. ``warpcloth list --examples`` prints their paths,
``python -m warpcloth.examples`` copies them into ./examples, ``warpcloth sweep --example quick``
runs a test list, ``python -m warpcloth.examples.drive`` drives a cloth from a frame loop."""
